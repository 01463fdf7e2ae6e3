"""The planner node's parameters beyond the NMPC's: its input topics, the shared ``/**``
section, and the wall-mode control-rate rule; ``trust-av`` reads the same classes
(:mod:`trust_av.system.config`), so the CLI and the node check them identically.
"""

from __future__ import annotations

from dataclasses import dataclass

from trust_av_common.params import MAX_VEHICLE_LENGTH_M, ParamsError, check_fields, param, require
from trust_av_common.topics import is_topic_name
from trust_av_planner.nmpc import PlannerConfig, prediction_grid

__all__ = ['PlannerTopics', 'SharedConfig', 'check_control_rate']


@dataclass(frozen=True)
class SharedConfig:
    """Parameters in the ``/**`` section that are not owned by one component."""

    vehicle_length_m: float = param('vehicle length: odometry position to bumper-to-bumper gap',
                                    unit='m', low=0.0, high=MAX_VEHICLE_LENGTH_M)
    speed_max_from_trace: bool = param('use max(v_PT) of the trace as the speed bound '
                                       '(Table I)')
    safety_gap_margin_m: float = param('a gap below d_s minus this margin is counted as unsafe',
                                       unit='m', low=0.0, high=1000.0)

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


def check_control_rate(planner: PlannerConfig, control_rate_hz: float) -> None:
    """The wall-mode control rate must give the NMPC a prediction grid
    (:func:`~trust_av_planner.nmpc.prediction_grid`: a period no longer than ``dt_s``, at
    most its largest grid); checked in wall mode by ``trust-av`` and by the planner node
    alike (lock-step does not use it).

    Raises:
        ParamsError: one line naming ``control_rate_hz``.
    """
    try:
        prediction_grid(planner, 1.0 / control_rate_hz)
    except (ValueError, ArithmeticError) as err:    # 1e308 Hz: an infinite step count
        raise ParamsError(f'control_rate_hz {control_rate_hz:g}: {err}') from err
