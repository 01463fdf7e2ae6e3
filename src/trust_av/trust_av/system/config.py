"""Load the whole run configuration from ROS 2 params files in layers.

The shipped ``config/trust_av.yaml`` is always the bottom layer; every ``--params-file``
goes over it in order, by rcl's rules (:mod:`trust_av_common.param_layers`), and the
nodes of the graph get the same files in the same order (:attr:`RunConfig.params_files`).
Every section must name a node of the graph or be a wildcard, every key must belong to a
component of that node (typos are errors), and every value is type- and range-checked by
the component's frozen dataclass, exactly as the nodes check them.
"""

from __future__ import annotations

import dataclasses
import re
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from human_driver_sim.driver_mpc import DriverConfig
from human_driver_sim.followers import DRIVERS, FollowerConfig
from preceding_traffic.traces import SpeedTrace, TraceConfig
from trust_av_common import registry
from trust_av_common.envelope import EnvelopeConfig, InputRanges
from trust_av_common.errors import did_you_mean, with_suggestions
from trust_av_common.frames import FrameConfig
from trust_av_common.lifecycle import LifecycleConfig
from trust_av_common.param_layers import (
    Layered,
    layer_files,
    layered_params,
    node_fqn,
    read_layers,
    section_target,
    shipped_params_file,
    text_layer,
)
from trust_av_common.params import (
    ParamsError,
    build_config,
    check_known,
)
from trust_av_common.rcl_values import ParsedParams
from trust_av_common.wall_clock import WallClockConfig
from trust_av_planner.nmpc import PlannerConfig
from trust_av_planner.planner_params import PlannerTopics, SharedConfig, check_control_rate
from trust_av_planner.predictors import PREDICTORS
from trust_monitor.model_interface import (
    TRUST_MODELS,
    TrustModel,
    make_trust_model,
    trust_model_config_types,
)
from trust_monitor.paper_trust import MonitorConfig, TrustConfig

__all__ = ['COMPONENT_GROUPS', 'DEFAULT_PARAMS_FILE', 'GROUPS', 'HUMAN_CAUTIOUS_PARAMS_FILE',
           'NODE_COMPONENTS', 'RunConfig', 'all_components', 'load_run_config', 'node_components']

DEFAULT_PARAMS_FILE = shipped_params_file()
"""The shipped params file (``config/trust_av.yaml``; ``share/trust_av_common/config/`` when
installed by colcon): the bottom layer of every run."""
HUMAN_CAUTIOUS_PARAMS_FILE = DEFAULT_PARAMS_FILE.with_name('human_cautious.yaml')
"""Profile layer with the cautious human driver (docs/DRIVER_IRL.md): the follower plans its gap
bound against the AV braking at u_R,min whatever it expects, and never comes closer than d_s."""


T = TypeVar('T')

# Node name -> the configuration classes its section may hold: what the node declares
# (tests/graph/test_node_params.py reads the nodes' declare_config calls), except the values
# trust-av sets per run, plus SharedConfig where trust-av itself reads it (the metrics'
# margin and the gaps of the in-process loop come from the preceding_traffic section).
# The parameters of the registered components come on top (node_components); the trust
# models' own parameters belong to the planner (its trust constraint) and the monitor alike.
TRUST_MODEL_CONFIGS = trust_model_config_types()
NODE_COMPONENTS: dict[str, tuple[type, ...]] = {
    'preceding_traffic': (TraceConfig, SharedConfig, WallClockConfig),
    'planner': (PlannerConfig, TrustConfig, SharedConfig, WallClockConfig, PlannerTopics,
                FrameConfig, LifecycleConfig, InputRanges, EnvelopeConfig),
    'human_driver': (DriverConfig, FollowerConfig, SharedConfig, WallClockConfig),
    'trust_monitor': (TrustConfig, WallClockConfig, MonitorConfig, LifecycleConfig,
                      InputRanges),
}

COMPONENT_GROUPS: dict[str, tuple[str, ...]] = {
    'planner': (PREDICTORS, TRUST_MODELS),
    'human_driver': (DRIVERS,),
    'trust_monitor': (TRUST_MODELS,),
}
"""Node name -> the registry groups whose components it runs: it declares the parameters of
every registered component of them (each validated, so a typo fails whichever is chosen)."""
GROUPS = (PREDICTORS, TRUST_MODELS, DRIVERS)
"""Every component group the application runs (each declared by the package that owns its
interface)."""


def node_components(node: str) -> tuple[type, ...]:
    """The configuration classes of ``node``'s section: :data:`NODE_COMPONENTS` and the
    ``config_type`` of every registered component the node runs.

    Raises:
        RegistryError: a registered component fails to load.
    """
    return NODE_COMPONENTS[node] + tuple(
        cls for group in COMPONENT_GROUPS.get(node, ()) for cls in registry.config_types(group))


def all_components() -> tuple[type, ...]:
    """Every configuration class of any node section (what a ``/**`` key may belong to)."""
    return tuple(dict.fromkeys(c for node in NODE_COMPONENTS for c in node_components(node)))

RUN_SET_NODES = ('ego_plant', 'recorder')
"""Nodes of the graph whose values trust-av gives them for each run (the simulated AV's
initial state, the recorder's bag); their clock settings come from /**."""

ONE_VALUE_PER_GRAPH: dict[str, str] = {
    **{f.name: 'the planner and the monitor must run the same trust model'
       for c in (TrustConfig, *TRUST_MODEL_CONFIGS) for f in dataclasses.fields(c)},
    **{f.name: 'the in-process loop and every node must see one vehicle geometry and one '
               'safety margin' for f in dataclasses.fields(SharedConfig)},
    'dt_s': 'the lock-step graph has one step',
    'clock_mode': 'the nodes of one graph run on one clock',
}
"""Parameters several nodes declare that must have one value in all of them (a node
section may set them only to the value every other node has): otherwise a graph run would
differ from the in-process loop, which has one value, or the lock-step graph would stall.
The other parameters several nodes share (``standstill_gap_m``, ``horizon_steps``, the
speed bounds) may differ per node: the AV's and the human's models are separate in both."""


@dataclass(frozen=True)
class RunConfig:
    """Everything one closed-loop run needs.

    Attributes:
        params_files: the params files it was read from, bottom (the shipped file) first:
            hand them to every node in this order (``--params-file`` once each).
        namespace: the namespace its node names were matched in.
        clock: the planner's wall-clock settings (its ``clock_mode`` is every node's).
        planner_topics: the planner's input topics.
        follower: which follower model drives behind the AV.
        predictor_configs: (name, parameters) of every registered plan estimator that has
            parameters (its ``config_type``, read from the planner's section).
        driver_configs: the same for the follower models (the human_driver section).
        ignored: one line per wildcard-section parameter that no node of the graph has
            (accepted: a shared bring-up file feeds other stacks' nodes too).
    """

    shared: SharedConfig
    trace: TraceConfig
    planner: PlannerConfig
    driver: DriverConfig
    trust: TrustConfig
    params_files: tuple[Path, ...] = field(default=(), compare=False)
    namespace: str = '/'
    clock: WallClockConfig = field(default_factory=WallClockConfig, compare=False)
    planner_topics: PlannerTopics = field(default_factory=PlannerTopics, compare=False)
    trust_model_params: tuple[tuple[str, Any], ...] = ()
    ignored: tuple[str, ...] = field(default=(), compare=False)
    follower: FollowerConfig = field(default_factory=FollowerConfig)
    predictor_configs: tuple[tuple[str, Any], ...] = ()
    driver_configs: tuple[tuple[str, Any], ...] = ()
    node_params: Mapping[str, Mapping[str, Any]] = field(default_factory=dict, compare=False)
    """Node name -> every parameter it declares and its effective value (all params-file
    layers and the command line's overrides merged, defaults filled in): what a run's
    record keeps (:mod:`trust_av.system.run_record`)."""

    def trust_model(self) -> TrustModel:
        """A fresh instance of the trust model ``trust.trust_model`` with its parameters."""
        return make_trust_model(self.trust, dict(self.trust_model_params))

    @property
    def predictor_params(self) -> Any:
        """The chosen plan estimator's parameters (None: it has none, or its defaults)."""
        return dict(self.predictor_configs).get(self.planner.predictor)

    @property
    def driver_params(self) -> Any:
        """The chosen follower model's parameters (None: it has none, or its defaults)."""
        return dict(self.driver_configs).get(self.follower.driver_model)

    @property
    def min_safe_gap_m(self) -> float:
        """Smallest gap counted as safe: d_s - safety_gap_margin_m."""
        return self.planner.standstill_gap_m - self.shared.safety_gap_margin_m

    def for_trace(self, trace: SpeedTrace) -> RunConfig:
        """Apply Table I's ``v_max = max(v_PT)`` when ``speed_max_from_trace`` is set."""
        if not self.shared.speed_max_from_trace:
            return self
        vmax = trace.max_speed_mps
        if not vmax > self.planner.speed_min_mps:
            raise ParamsError(
                f'{trace.source or trace.name}: the lead never moves faster than '
                f'speed_min_mps = {self.planner.speed_min_mps:g} m/s (its highest speed is '
                f"{vmax:g} m/s), and speed_max_from_trace takes both vehicles' speed limit "
                'from it; use a trace in which the lead moves, or speed_max_from_trace: false '
                'with speed_max_mps')
        node_params = {node: ({**values, 'speed_max_mps': vmax} if 'speed_max_mps' in values
                              else values) for node, values in self.node_params.items()}
        return dataclasses.replace(
            self, planner=dataclasses.replace(self.planner, speed_max_mps=vmax),
            driver=dataclasses.replace(self.driver, speed_max_mps=vmax),
            node_params=node_params)


OVERRIDES_WHERE = 'command-line options'


def check_sections(layers: Sequence[ParsedParams]) -> list[str]:
    """Every section names a node of the graph (or is a wildcard) and holds only parameters
    of that node's components. A wildcard section of a file may hold other names (a shared
    bring-up file feeds other stacks' nodes too; rclpy ignores what a node does not
    declare): they are returned, one line each; on the command line they are typos.

    Returns:
        One line per file and wildcard section naming the parameters no node has.

    Raises:
        ParamsError: one line naming the file, the section and the unknown name.
    """
    every = all_components()
    ignored = []
    for layer in layers:
        for section, values in layer.items():
            target = section_target(section)
            if target is None and layer.where != OVERRIDES_WHERE:
                known = {f.name for c in every for f in dataclasses.fields(c)}
                unknown = sorted(set(values) - known)
                if unknown:
                    ignored.append(f'{layer.where}: section {section}: ignoring '
                                   f'{with_suggestions(unknown, known)} (not a parameter of '
                                   'any node of the graph)')
            elif target is None:
                check_known(values, *every, where=f'{layer.where}: section {section}')
            elif target in NODE_COMPONENTS:
                check_known(values, *node_components(target),
                            where=f'{layer.where}: section {section}')
            elif target in RUN_SET_NODES:
                raise ParamsError(f'{layer.where}: section {section!r}: trust-av sets the '
                                  f"{target} node's values for each run (its clock settings "
                                  'come from /**); node sections: '
                                  f'{", ".join(NODE_COMPONENTS)}')
            else:
                node = section.rstrip('/').rsplit('/', 1)[-1]
                raise ParamsError(f'{layer.where}: unknown node section {section!r} (known: '
                                  f'{", ".join(NODE_COMPONENTS)}, or a wildcard such as /** '
                                  f'or /**/planner){did_you_mean(node, NODE_COMPONENTS)}')
    return ignored


def load_run_config(files: str | Path | Iterable[str | Path] = (),
                    overrides: Mapping[str, Mapping[str, Any]] | None = None, *,
                    namespace: str = '/') -> RunConfig:
    """Read and validate the run configuration: the shipped params file, then ``files``.

    Args:
        files: params files over the shipped one, in command-line order (one path or
            several; the shipped file itself may be given first, it is not read twice).
        overrides: node name (or ``/**``) to values given on the command line; they go over
            every file, as the section ``<namespace>/<node>`` of one more layer.
        namespace: the nodes' namespace; sections are matched against
            ``<namespace>/<node>`` as rclpy matches them.

    Returns:
        The configuration; its ``params_files`` are the files read, bottom first.

    Raises:
        ParamsError: an unreadable file, what rcl would refuse, an unknown node section or
            parameter, a later value that would not reach a node, a wrong type, a value out
            of range (one line naming the file, node or parameter).
    """
    paths = layer_files(files)
    layers = read_layers(paths)
    if overrides:
        layers.append(text_layer(
            {(name if section_target(name) is None else node_fqn(namespace, name)): values
             for name, values in overrides.items() if values}, OVERRIDES_WHERE))
    ignored = check_sections(layers)
    for line in ignored:
        print(f'warning: {line}', file=sys.stderr)
    # Every component each node will declare, built once (a node refuses what fails here).
    built: dict[tuple[str, type], Any] = {}
    sources: dict[str, Mapping[str, str]] = {}
    for node in NODE_COMPONENTS:
        params = layered_params(layers, node_fqn(namespace, node))
        sources[node] = params.sources
        for component in node_components(node):
            built[node, component] = _build(component, params)
    check_one_value_per_graph(built, sources)
    trust: TrustConfig = built['trust_monitor', TrustConfig]
    model_params = tuple((f.name, getattr(config, f.name))
                         for (node, kind), config in built.items()
                         if node == 'trust_monitor' and kind in TRUST_MODEL_CONFIGS
                         for f in dataclasses.fields(config))
    make_trust_model(trust, dict(model_params))  # an unregistered name: refused here
    planner: PlannerConfig = built['planner', PlannerConfig]
    configs = {group: tuple((c.name, built[node, c.config_type])
                            for c in registry.components(group) if c.config_type is not None)
               for node, groups in COMPONENT_GROUPS.items() for group in groups
               if group != TRUST_MODELS}
    clock: WallClockConfig = built['planner', WallClockConfig]
    if clock.wall:
        check_control_rate(planner, clock.control_rate_hz)
    return RunConfig(
        clock=clock,
        planner_topics=built['planner', PlannerTopics],
        shared=built['preceding_traffic', SharedConfig],
        trace=built['preceding_traffic', TraceConfig],
        planner=planner,
        driver=built['human_driver', DriverConfig],
        trust=trust,
        trust_model_params=model_params,
        params_files=paths,
        namespace=namespace,
        follower=built['human_driver', FollowerConfig],
        predictor_configs=configs[PREDICTORS],
        driver_configs=configs[DRIVERS],
        ignored=tuple(ignored),
        node_params={node: {f.name: getattr(config, f.name)
                            for (owner, _), config in built.items() if owner == node
                            for f in dataclasses.fields(config)}
                     for node in NODE_COMPONENTS},
    )


def check_one_value_per_graph(built: Mapping[tuple[str, type], Any],
                              sources: Mapping[str, Mapping[str, str]]) -> None:
    """Every parameter of :data:`ONE_VALUE_PER_GRAPH` has the same value in every node
    that has it.

    Args:
        built: (node, component) -> the component as that node builds it.
        sources: node -> the file each of its values came from.

    Raises:
        ParamsError: one line naming the parameter, two nodes and their values, the file(s)
            that set them, and why it must be one value.
    """
    for name, why in ONE_VALUE_PER_GRAPH.items():
        values: dict[str, Any] = {}
        for (node, _component), config in built.items():
            if hasattr(config, name):
                values.setdefault(node, getattr(config, name))
        distinct = list(dict.fromkeys(values.values()))
        if len(distinct) > 1:
            first, other = (next(n for n, v in values.items() if v == d) for d in distinct[:2])
            # The files in the order the nodes are named (never sorted: a path's place
            # would then depend on where the checkout and the user's file live).
            where = list(dict.fromkeys(sources[n][name] for n in (first, other)
                                       if name in sources[n]))
            prefix = f'{", ".join(where)}: ' if where else ''
            raise ParamsError(f'{prefix}{name} is {values[first]!r} for '
                              f'{first} but {values[other]!r} for {other}: {why}; set it '
                              'once, in /**')


def _build(cls: type[T], params: Layered) -> T:
    """:func:`build_config`, its error prefixed with the file(s) that set the named values."""
    try:
        return build_config(cls, params)
    except ParamsError as err:
        named = [f.name for f in dataclasses.fields(cls)  # type: ignore[arg-type]
                 if re.search(rf'\b{f.name}\b', str(err)) and f.name in params.sources]
        where = list(dict.fromkeys(params.sources[name] for name in named))
        if not where:
            raise
        raise ParamsError(f'{", ".join(where)}: {err}') from err
