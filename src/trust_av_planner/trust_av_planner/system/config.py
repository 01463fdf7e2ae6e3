"""Load the whole run configuration from one ROS 2 params file (``config/trust_av.yaml``).

The in-process simulator and the node graph read the same file; every key must belong to
a known component (typos are errors), every value is type- and range-checked by the
component's frozen dataclass.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from human_driver_sim.driver_mpc import DriverConfig
from preceding_traffic.traces import SpeedTrace, TraceConfig
from trust_av_planner.nmpc import PlannerConfig
from trust_monitor.common.params import (
    WILDCARD,
    ParamsError,
    build_config,
    check_fields,
    check_known,
    node_params,
    param,
    read_params_file,
    require,
)
from trust_monitor.common.topics import is_topic_name
from trust_monitor.common.wall_clock import WallClockConfig
from trust_monitor.trust_model import TrustConfig

DEFAULT_PARAMS_FILE = Path(__file__).resolve().parents[1] / 'config' / 'trust_av.yaml'
"""The shipped params file (``config/trust_av.yaml`` of the repository)."""


@dataclass(frozen=True)
class SharedConfig:
    """Parameters in the ``/**`` section that are not owned by one component."""

    vehicle_length_m: float = param('vehicle length: odometry position to bumper-to-bumper gap',
                                    unit='m', low=0.0)
    speed_max_from_trace: bool = param('use max(v_PT) of the trace as the speed bound '
                                       '(Table I)')
    safety_gap_margin_m: float = param('a gap below d_s minus this margin is counted as unsafe',
                                       unit='m', low=0.0)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class PlannerTopics:
    """The planner's input topics: a real vehicle's topics are plugged in here (params file
    or the orchestrator's per-run file), no code change. An empty ``human_odom_topic`` means
    there is no follower state (wall mode only: the plan estimator then observes nothing)."""

    lead_odom_topic: str = param('preceding vehicle odometry topic (nav_msgs/msg/Odometry)',
                                 default='preceding_vehicle/odom')
    lead_preview_topic: str = param('preceding vehicle speed preview topic (JointTrajectory)',
                                    default='preceding_vehicle/speed_preview')
    ego_odom_topic: str = param('ego (AV) odometry topic (nav_msgs/msg/Odometry)',
                                default='ego/odom')
    human_odom_topic: str = param("human follower odometry topic ('' = none, wall mode only)",
                                  default='human/odom')
    trust_topic: str = param('trust estimate topic (geometry_msgs/msg/Vector3Stamped)',
                             default='trust_monitor/trust')

    def __post_init__(self) -> None:
        for name in ('lead_odom_topic', 'lead_preview_topic', 'ego_odom_topic', 'trust_topic',
                     'human_odom_topic'):
            value = getattr(self, name)
            require((name == 'human_odom_topic' and value == '') or is_topic_name(value),
                    f'{name} must be a ROS topic name (relative names resolve in the '
                    f"node's namespace), got {value!r}")


# Node name -> the configuration classes its section may hold.
NODE_COMPONENTS: dict[str, tuple[type, ...]] = {
    'preceding_traffic': (TraceConfig, SharedConfig),
    'planner': (PlannerConfig, TrustConfig, SharedConfig, WallClockConfig, PlannerTopics),
    'human_driver': (DriverConfig, SharedConfig),
    'trust_monitor': (TrustConfig, WallClockConfig),
}
_ALL = tuple({c for comps in NODE_COMPONENTS.values() for c in comps})


@dataclass(frozen=True)
class RunConfig:
    """Everything one closed-loop run needs."""

    shared: SharedConfig
    trace: TraceConfig
    planner: PlannerConfig
    driver: DriverConfig
    trust: TrustConfig

    @property
    def min_safe_gap_m(self) -> float:
        """Smallest gap counted as safe: d_s - safety_gap_margin_m."""
        return self.planner.standstill_gap_m - self.shared.safety_gap_margin_m

    def for_trace(self, trace: SpeedTrace) -> RunConfig:
        """Apply Table I's ``v_max = max(v_PT)`` when ``speed_max_from_trace`` is set."""
        if not self.shared.speed_max_from_trace:
            return self
        vmax = trace.max_speed_mps
        return dataclasses.replace(
            self, planner=dataclasses.replace(self.planner, speed_max_mps=vmax),
            driver=dataclasses.replace(self.driver, speed_max_mps=vmax))


def load_run_config(path: str | Path = DEFAULT_PARAMS_FILE,
                    overrides: Mapping[str, Mapping[str, Any]] | None = None) -> RunConfig:
    """Read and validate the params file, with optional per-node overrides.

    Args:
        path: ROS 2 params file.
        overrides: node name (or ``/**``) to parameter values that replace the file's.

    Raises:
        ParamsError: unknown node or parameter, wrong type, or a value out of range.
    """
    sections = read_params_file(path)
    for node, values in (overrides or {}).items():
        sections.setdefault(node, {}).update(values)
    for node, values in sections.items():
        if node == WILDCARD:
            check_known(values, *_ALL, where=f'{path}: section {node}')
        elif node in NODE_COMPONENTS:
            check_known(values, *NODE_COMPONENTS[node], where=f'{path}: section {node}')
        else:
            raise ParamsError(f'{path}: unknown node section {node!r} (known: '
                              f'{", ".join(NODE_COMPONENTS)})')
    traffic = node_params(sections, 'preceding_traffic')
    return RunConfig(
        shared=build_config(SharedConfig, traffic),
        trace=build_config(TraceConfig, traffic),
        planner=build_config(PlannerConfig, node_params(sections, 'planner')),
        driver=build_config(DriverConfig, node_params(sections, 'human_driver')),
        trust=build_config(TrustConfig, node_params(sections, 'trust_monitor')),
    )
