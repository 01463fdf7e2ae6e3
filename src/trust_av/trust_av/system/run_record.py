"""What a run's record says ran: the component of each group and the effective parameters of
every node (every params-file layer and the command line's overrides merged, defaults filled
in, and the values trust-av sets per run on top).

The same record goes into a graph run's bag (rosbag2 ``metadata.yaml`` ``custom_data``, and so
into the MCAP's ``rosbag2`` metadata record; :data:`PARAMS_KEY`, :data:`COMPONENT_KEYS`), its
logs (``BAG.logs/effective_params.yaml``) and the header ``trust-av run``, ``simulate`` and
``shadow`` print before they start (:func:`header`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import yaml

from human_driver_sim.followers import DRIVERS
from trust_av.system.config import RunConfig
from trust_av_common import registry
from trust_av_common.param_layers import node_fqn
from trust_av_planner.predictors import PREDICTORS
from trust_monitor.model_interface import TRUST_MODELS

__all__ = ['COMPONENT_KEYS', 'PARAMS_FILE_NAME', 'PARAMS_KEY', 'RECORD_FILE_NAME', 'custom_data',
           'header']

PARAMS_KEY = 'trust_av.params'
"""``custom_data`` key of the effective parameters (YAML text in params-file format: one
section per node under its fully qualified name)."""
COMPONENT_KEYS = {'predictor': 'trust_av.component.predictor',
                  'trust_model': 'trust_av.component.trust_model',
                  'driver_model': 'trust_av.component.driver_model'}
"""Group -> the ``custom_data`` key naming the registered component that ran in it."""
PARAMS_FILE_NAME = 'effective_params.yaml'
"""The logs' copy of the effective parameters (beside the nodes' logs)."""
RECORD_FILE_NAME = 'run_record.yaml'
"""The ``custom_data`` entries the recorder writes into the bag (in the logs directory)."""


def components(config: RunConfig) -> dict[str, str]:
    """Group -> the registered component that runs in it: the plan estimator (predictor),
    the trust model and the human follower model (driver_model)."""
    return {'predictor': config.planner.predictor, 'trust_model': config.trust.trust_model,
            'driver_model': config.follower.driver_model}


def _plain(value: Any) -> Any:
    """A parameter value as YAML holds it (tuples as lists, anything else as its text)."""
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    return str(value)


def effective_params(config: RunConfig,
                     per_run: Mapping[str, Mapping[str, Any]] | None = None
                     ) -> dict[str, dict[str, Any]]:
    """Node -> parameter -> the value it runs with.

    Args:
        config: the run's configuration (its ``node_params``: every layer merged).
        per_run: node -> the values trust-av gives it for this run (a graph's per-run
            parameters: the traffic's trace, the initial states, the recorder's bag), on top.
    """
    out: dict[str, dict[str, Any]] = {node: {name: _plain(value) for name, value
                                             in sorted(values.items())}
                                      for node, values in config.node_params.items()}
    for node, values in (per_run or {}).items():
        out.setdefault(node, {}).update({name: _plain(v) for name, v in values.items()})
    return out


def params_text(config: RunConfig,
                per_run: Mapping[str, Mapping[str, Any]] | None = None) -> str:
    """:func:`effective_params` as a params-file-shaped YAML document (one section per node
    under its fully qualified name in the run's namespace)."""
    sections = {node_fqn(config.namespace, node): {'ros__parameters': values}
                for node, values in effective_params(config, per_run).items()}
    return str(yaml.safe_dump(sections, default_flow_style=False, sort_keys=False))


def custom_data(config: RunConfig,
                per_run: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, str]:
    """The bag's ``custom_data`` entries of the record: each group's component and the
    effective parameters (string keys and values, as rosbag2 requires)."""
    entries = {COMPONENT_KEYS[group]: name for group, name in components(config).items()}
    entries[PARAMS_KEY] = params_text(config, per_run)
    return entries


def header(config: RunConfig) -> str:
    """One line naming what runs: ``components: predictor ca, trust model paper, driver
    model mpc; parameters: FILE + FILE`` (the params files, bottom first; the command
    line's options are over them). Each component is loaded first, so a plug-in that
    cannot load is the command's one line and is never named as running.

    Raises:
        RegistryError: a chosen component does not load.
    """
    for group, name in zip((PREDICTORS, TRUST_MODELS, DRIVERS),
                           components(config).values(), strict=True):
        registry.get(group, name)
    names = ', '.join(f'{group.replace("_", " ")} {name}'
                      for group, name in components(config).items())
    files = ' + '.join(str(path) for path in config.params_files) or 'defaults'
    return f'components: {names}; parameters: {files}'
