"""Pure-Python mirror of rcl's params-file rules (ROS 2 Jazzy); work in progress."""

from __future__ import annotations
