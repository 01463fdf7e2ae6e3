"""Nodes started by hand (``python -m``) on their own domain and driven through their
lifecycle as ``ros2 lifecycle set`` drives them (tests/graph/test_lifecycle.py has the rules)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

UNCONFIGURED, INACTIVE, ACTIVE = 1, 2, 3
CONFIGURE, ACTIVATE, DEACTIVATE = 1, 3, 4
STEP_NS = 100_000_000   # dt_s of the shipped file, 0.1 s


def start(tmp_path: Path, domain: int, module: str, *args: str) -> subprocess.Popen[str]:
    """A node started by hand, as a user does (``python -m``), on its own domain."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_LOG_DIR=str(tmp_path / 'ros_log'), PYTHONUNBUFFERED='1')
    return subprocess.Popen([sys.executable, '-m', module, '--ros-args', *args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env, start_new_session=True)


def stop(proc: subprocess.Popen[str]) -> str:
    """SIGINT the node; its whole output (it must exit 0)."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGINT)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0, out
    assert 'Traceback' not in out, out
    return out


class Manager:
    """This test's side: lifecycle service clients of one node, input publishers, and what
    the node published, on a private rclpy context."""

    def __init__(self, domain: int, name: str) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node('lifecycle_manager', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        from lifecycle_msgs.srv import ChangeState, GetState

        self.change = self.node.create_client(ChangeState, f'/{name}/change_state')
        self.get = self.node.create_client(GetState, f'/{name}/get_state')
        self.received: dict[str, list[Any]] = {}

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)

    def spin_until(self, done: Callable[[], bool], timeout_s: float = 60.0) -> bool:
        end = time.monotonic() + timeout_s
        while not done() and time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)
        return done()

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)

    def call(self, client: Any, request: Any) -> Any:
        assert self.spin_until(client.service_is_ready), client.srv_name
        future = client.call_async(request)
        assert self.spin_until(future.done), client.srv_name
        return future.result()

    def state(self) -> int:
        """The node's state, asked again while no answer comes, as the orchestrator asks (a
        service is ready once its request topic is matched, and an answer sent before the
        client's answer topic is matched is lost)."""
        from lifecycle_msgs.srv import GetState

        from trust_av.graph.lifecycle_client import _ask

        assert self.spin_until(self.get.service_is_ready), self.get.srv_name
        answer = _ask(self.executor, self.get, GetState.Request(), time.monotonic() + 60.0,
                      self.get.srv_name, lambda: None)
        return int(answer.current_state.id)

    def transition(self, transition_id: int) -> bool:
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState

        request = ChangeState.Request(transition=Transition(id=transition_id))
        return bool(self.call(self.change, request).success)

    def record(self, msgtype: Any, topic: str, qos: Any) -> None:
        self.received[topic] = []
        self.node.create_subscription(msgtype, topic, self.received[topic].append, qos)
