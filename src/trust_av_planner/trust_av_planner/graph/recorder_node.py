"""``recorder`` node (``ros2 run trust_av_planner recorder``): raw subscriptions to every
topic of the graph that lists it as a subscriber, written as they came over DDS into one MCAP
(:class:`trust_av_planner.graph.recorder.McapBag`); it ends by itself once it holds every
message of ``expected_steps`` steps.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from rclpy.node import Node

from trust_av_planner.graph.recorder import McapBag
from trust_monitor.common.params import check_fields, param
from trust_monitor.common.topics import TOPICS
from trust_monitor.ros.messages import message_class
from trust_monitor.ros.parameters import declare_config
from trust_monitor.ros.qos import QOS
from trust_monitor.ros.spin import spin_node


@dataclass(frozen=True)
class RecorderConfig:
    """Where to record and when the run is complete."""

    bag_path: str = param('MCAP file to write')
    expected_steps: int = param('the run is complete after this many steps', low=0)

    def __post_init__(self) -> None:
        check_fields(self)


class RecorderNode(Node):
    """Raw subscriptions to every topic of the table; one MCAP file."""

    def __init__(self) -> None:
        super().__init__('recorder')
        self.config = declare_config(self, RecorderConfig)
        self.bag = McapBag(Path(self.config.bag_path))
        self.finished = False
        self.expected: dict[str, int] = {}
        steps = self.config.expected_steps
        for topic in TOPICS:
            if 'recorder' not in topic.subscribers:
                continue
            name = self.resolve_topic_name(topic.name)  # the bag holds full names
            self.bag.add_topic(name, topic.msgtype, topic.qos)
            self.expected[name] = topic.messages(steps)
            self.create_subscription(message_class(topic.msgtype), topic.name,
                                     lambda data, t=name: self.on_message(t, data),
                                     QOS[topic.qos], raw=True)
        self.clock_topic = self.resolve_topic_name('clock')
        self.get_logger().info(f'ready: recording {len(self.expected)} topics to '
                               f'{self.bag.path}')

    def on_message(self, topic: str, data: bytes) -> None:
        """Write one raw message; finish when every topic holds every step."""
        if self.finished:
            return
        self.bag.write(topic, data)
        if topic == self.clock_topic:
            self.bag.flush()
        if all(self.bag.counts[t] >= n for t, n in self.expected.items()):
            self.get_logger().info(f'recorded {sum(self.bag.counts.values())} messages '
                                   f'to {self.bag.path}')
            self.close()
            self.finished = True

    def close(self) -> None:
        """Finish the MCAP file (also on a stop request)."""
        self.bag.finish()


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run trust_av_planner recorder``."""
    return spin_node(RecorderNode, args)


if __name__ == '__main__':
    sys.exit(main())
