"""Managed (lifecycle) nodes, pure part: the one parameter that says who drives a node's
transitions, and what each state means for the planner and the trust monitor.

The states and transitions are ROS 2's (https://design.ros2.org/articles/node_lifecycle.html,
implemented by ``rcl_lifecycle/src/default_state_machine.c`` and driven from Python by
``rclpy/lifecycle/node.py``): ``unconfigured`` -configure-> ``inactive`` -activate->
``active`` -deactivate-> ``inactive`` -cleanup-> ``unconfigured``; ``shutdown`` from any of
the three ends in ``finalized``.
"""

from __future__ import annotations

from dataclasses import dataclass

from trust_av_common.params import param

__all__ = ['LifecycleConfig']

AUTOSTART_REASON = 'read once when the node is made, before it is configured'


@dataclass(frozen=True)
class LifecycleConfig:
    """Who drives the transitions of a managed node (planner, trust_monitor).

    Attributes:
        autostart: True: the node configures itself when it starts (a bad parameter ends
            the process with one line, exit 2) and, with ``clock_mode: lockstep``, also
            activates itself, so a ``trust-av run`` graph needs no manager; with
            ``clock_mode: wall`` it stays ``inactive`` until a lifecycle manager (or
            ``ros2 lifecycle set``) activates it. False: it waits ``unconfigured`` for a
            ``configure`` transition (``trust-av shadow`` starts its nodes so).
    """

    autostart: bool = param('configure at start-up and, in lockstep clock mode, activate; '
                            'false: wait for lifecycle transitions (ros2 lifecycle set)',
                            default=True, reason=AUTOSTART_REASON)
