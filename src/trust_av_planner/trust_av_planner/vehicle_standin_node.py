"""``vehicle_standin`` node: a stand-in for a real vehicle, on a vehicle's own topic names.

What a vehicle team's stack does around the planner, simulated at real time: its odometry on
``/vehicle/odom``, its perception's lead vehicle on ``/perception/lead_vehicle/odom`` (both
``nav_msgs/Odometry``, sensor-data QoS with an offered deadline) and its drive-by-wire taking
``/control/accel_cmd`` (``geometry_msgs/AccelStamped``, command QoS). The planner and the trust
monitor are connected to it by remapping only (``benchmarks/vehicle_loop.py``).

A timer at twice ``control_rate_hz`` alternates: on even ticks the vehicle applies the newest
command if it is younger than its deadline (two control periods, by its stamp; otherwise it
coasts: a drive-by-wire unit drops a stale set-point), integrates over the real elapsed time
and measures itself and the lead (a trace replayed at real time); on odd ticks, half a
period later (the input delay: 50 ms at 10 Hz), it publishes that measurement (stamped with
the measurement time), dropping each
message with probability ``drop_fraction`` and the lead's for ``outage_s`` from
``outage_start_s``. It also logs the planner status and the trust it hears. After
``duration_s`` it writes everything to ``report_path`` (JSON) and exits.
"""

from __future__ import annotations

import json
import random
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.node import Node

from preceding_traffic.replay import LeadReplay
from preceding_traffic.sources import load_trace
from preceding_traffic.traces import TraceConfig
from trust_av_common.kinematics import advance
from trust_av_common.output_files import write_text
from trust_av_common.params import (
    MAX_STAMP_S,
    MAX_VEHICLE_LENGTH_M,
    check_fields,
    param,
)
from trust_av_common.ros.messages import diagnostic_values, msg_ns, odometry
from trust_av_common.ros.parameters import declare_config
from trust_av_common.ros.qos import command_deadline_s, topic_qos
from trust_av_common.ros.spin import spin_node
from trust_av_common.wall_clock import NS_PER_S, WallClockConfig

__all__ = ['main']

EGO_TOPIC = '/vehicle/odom'
LEAD_TOPIC = '/perception/lead_vehicle/odom'
COMMAND_TOPIC = '/control/accel_cmd'


@dataclass(frozen=True)
class StandinConfig:
    """The stand-in vehicle's run."""

    trace: str = param('lead vehicle: shipped trace, CSV or bag', default='commute_am')
    duration_s: float = param('wall time driven', unit='s', low=0.0, low_inclusive=False,
                              high=MAX_STAMP_S, default=60.0)
    drop_fraction: float = param('probability that a measurement message is dropped',
                                 low=0.0, high=1.0, default=0.05)
    outage_start_s: float = param('start of the lead-input outage', unit='s', low=0.0,
                                  high=MAX_STAMP_S, default=30.0)
    outage_s: float = param('length of the lead-input outage (0: none)', unit='s', low=0.0,
                            high=MAX_STAMP_S, default=1.0)
    seed: int = param('seed of the drops', low=0, high=2**32 - 1, default=1)
    initial_gap_m: float = param('initial bumper-to-bumper gap', unit='m', low=0.0,
                                 high=10_000.0, default=5.0)
    vehicle_length_m: float = param('vehicle length', unit='m', low=0.0,
                                    high=MAX_VEHICLE_LENGTH_M, default=4.5)
    report_path: str = param('JSON report written at the end', default='')

    def __post_init__(self) -> None:
        check_fields(self)


class StandinNode(Node):
    """The stand-in vehicle (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__('vehicle_standin')
        self.finished = False
        self.stopping = False  # set by spin_node on a stop request
        self.exit_code = 0
        self.config = declare_config(self, StandinConfig)
        self.clock = declare_config(self, WallClockConfig)
        c = self.config
        trace = load_trace(c.trace, 1.0, TraceConfig(trace=c.trace, max_sample_gap_s=5.0))
        self.lead = LeadReplay(trace, c.initial_gap_m + c.vehicle_length_m)
        self.ego_m, self.ego_mps = 0.0, float(trace.speeds_mps[0])
        self.deadline_s = command_deadline_s(self.clock)
        self.random = random.Random(c.seed)
        self.pub_ego = self.create_publisher(Odometry, EGO_TOPIC,
                                             topic_qos('ego/odom', self.clock, publisher=True))
        self.pub_lead = self.create_publisher(
            Odometry, LEAD_TOPIC, topic_qos('preceding_vehicle/odom', self.clock,
                                            publisher=True))
        self.command: AccelStamped | None = None
        self.create_subscription(AccelStamped, COMMAND_TOPIC, self.on_command,
                                 topic_qos('ego/accel_cmd', self.clock))
        self.create_subscription(DiagnosticArray, 'ego/planner_status', self.on_status,
                                 topic_qos('ego/planner_status', self.clock))
        self.create_subscription(Vector3Stamped, 'trust_monitor/trust', self.on_trust,
                                 topic_qos('trust_monitor/trust', self.clock))
        self.log: dict[str, list[dict[str, Any]]] = {'ticks': [], 'status': [], 'trust': [],
                                                     'sent': []}
        self.start_ns: int | None = None
        self.last_ns = 0
        self.pending: list[tuple[str, Odometry]] = []
        self.even = True
        self.create_timer(0.5 / self.clock.control_rate_hz, self.tick)
        self.get_logger().info(f'ready: {c.trace} for {c.duration_s:g} s at '
                               f'{self.clock.control_rate_hz:g} Hz, delay '
                               f'{0.5 / self.clock.control_rate_hz:g} s, '
                               f'drops {c.drop_fraction:.0%}, lead outage {c.outage_s:g} s at '
                               f'{c.outage_start_s:g} s; waiting for the planner')

    def elapsed_s(self, now_ns: int) -> float:
        """Seconds since the run started (0 before)."""
        return 0.0 if self.start_ns is None else (now_ns - self.start_ns) / NS_PER_S

    def on_command(self, msg: AccelStamped) -> None:
        """Keep the newest command."""
        self.command = msg

    def on_status(self, msg: DiagnosticArray) -> None:
        """Log the planner's status."""
        values = diagnostic_values(msg)
        self.log['status'].append({'t_s': self.elapsed_s(time.time_ns()),
                                   'level': int.from_bytes(msg.status[0].level, 'little')
                                   if isinstance(msg.status[0].level, bytes)
                                   else int(msg.status[0].level),
                                   'status': values.get('status', ''),
                                   'reason': values.get('reason', ''),
                                   'command_mps2': float(values.get('command_mps2', 'nan'))})

    def on_trust(self, msg: Vector3Stamped) -> None:
        """Log the trust estimate."""
        self.log['trust'].append({'t_s': self.elapsed_s(time.time_ns()),
                                  'explicability': msg.vector.x, 'trust': msg.vector.z})

    def connected(self) -> bool:
        """The planner subscribes to both inputs and the trust monitor publishes."""
        return (self.count_subscribers(EGO_TOPIC) >= 1 and self.count_subscribers(LEAD_TOPIC)
                >= 1 and self.count_publishers(COMMAND_TOPIC) >= 1
                and self.count_publishers('trust_monitor/trust') >= 1)

    def tick(self) -> None:
        """Even ticks: drive and measure; odd ticks: publish the measurement."""
        now = time.time_ns()
        if self.start_ns is None:
            if not self.connected():
                return
            self.start_ns = self.last_ns = now
            self.get_logger().info('connected: driving')
        self.even = not self.even
        if not self.even:
            self.drive(now)
        else:
            for topic, msg in self.pending:
                (self.pub_lead if topic == 'lead' else self.pub_ego).publish(msg)
            self.pending = []
        if self.elapsed_s(now) >= self.config.duration_s:
            self.finish()

    def drive(self, now: int) -> None:
        """Apply the newest fresh command over the elapsed time, then measure."""
        t = self.elapsed_s(now)
        command = self.command
        age = None if command is None else (now - msg_ns(command.header.stamp)) / NS_PER_S
        fresh = command is not None and age is not None and age <= self.deadline_s
        applied = float(command.accel.linear.x) if fresh and command is not None else 0.0
        self.ego_m, self.ego_mps = advance(self.ego_m, self.ego_mps, applied,
                                           (now - self.last_ns) / NS_PER_S)
        self.last_ns = now
        lead = self.lead.state(t)
        gap = lead.position_m - self.ego_m - self.config.vehicle_length_m
        self.log['ticks'].append({'t_s': t, 'gap_m': gap, 'ego_speed_mps': self.ego_mps,
                                  'lead_speed_mps': lead.speed_mps, 'applied_mps2': applied,
                                  'command_age_s': age if fresh else None,
                                  'stale_command_age_s': None if fresh else age})
        c = self.config
        in_outage = c.outage_start_s <= t < c.outage_start_s + c.outage_s
        for topic, (position, speed), frame in (
                ('ego', (self.ego_m, self.ego_mps), 'vehicle'),
                ('lead', (lead.position_m, lead.speed_mps), 'lead_vehicle')):
            dropped = self.random.random() < c.drop_fraction
            sent = not dropped and not (topic == 'lead' and in_outage)
            self.log['sent'].append({'t_s': t, 'topic': topic, 'sent': sent})
            if sent:
                self.pending.append((topic, odometry(now, position, speed, frame)))

    def finish(self) -> None:
        """Write the report and end the node."""
        if self.config.report_path:
            write_text(Path(self.config.report_path), json.dumps(
                {'config': self.config.__dict__, 'command_deadline_s': self.deadline_s,
                 **self.log}))
        self.finished = True

    def close(self) -> None:
        """Nothing to release."""


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m trust_av_planner.vehicle_standin_node --ros-args ...``."""
    return spin_node(StandinNode, args)


if __name__ == '__main__':
    sys.exit(main())
