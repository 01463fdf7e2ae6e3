"""The pure core never imports rclpy or message packages (HOUSE_STYLE rule 1)."""

from __future__ import annotations

import subprocess
import sys

CORE_MODULES = [
    'preceding_traffic.traces',
    'trust_monitor.params', 'trust_monitor.trust_model', 'trust_monitor.estimate',
    'human_driver_sim.longitudinal', 'human_driver_sim.driver_mpc', 'human_driver_sim.solver',
    'trust_av_planner.nmpc', 'trust_av_planner.config', 'trust_av_planner.plant',
    'trust_av_planner.planner_core', 'trust_av_planner.simulate',
    'trust_av_planner.predictors.ca', 'trust_av_planner.cmd_simulate',
]


def test_core_imports_no_ros() -> None:
    code = ('import sys\n'
            f'for m in {CORE_MODULES!r}: __import__(m)\n'
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
            "{'rclpy', 'std_msgs', 'nav_msgs', 'geometry_msgs', 'trajectory_msgs', "
            "'diagnostic_msgs', 'rosgraph_msgs', 'builtin_interfaces'})\n"
            'print(bad)\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == '[]', out.stdout
