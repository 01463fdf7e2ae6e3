"""The planner node with an internal error injected: its 5th planning step raises
``RuntimeError('injected internal error')`` (a bug no message can provoke any more, since every
value is checked where it enters). Started as ``python -m support.faulty_planner --ros-args
...`` by tests/graph/test_value_fuzz.py to see the hand-over on the wire."""

from __future__ import annotations

import sys
from typing import Any

from trust_av_planner import planner_node

FAIL_AT = 5
_original = planner_node.PlannerNode.plan
_calls = [0]


def _plan(self: Any, *args: Any, **kwargs: Any) -> None:
    _calls[0] += 1
    if _calls[0] == FAIL_AT:
        raise RuntimeError('injected internal error')
    _original(self, *args, **kwargs)


planner_node.PlannerNode.plan = _plan  # type: ignore[method-assign]

if __name__ == '__main__':
    sys.exit(planner_node.main())
