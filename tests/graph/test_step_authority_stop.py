"""A stop request ends the lock-step chain at the step in progress.

On SIGINT/SIGTERM a node keeps taking what is queued for a moment (``spin_node``'s drain),
so that a recorder stopped after it holds every complete step. The step authority
(``preceding_traffic``) must not start new steps meanwhile: otherwise a stopped run goes on
for the whole drain (64 further steps in one suite run), whose messages a recorder behind on
a loaded machine has not acknowledged when their writers exit, so whole topics of the bag
end 64 steps before the others. The real node class, in a fresh rclpy process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from trust_av.system.config import DEFAULT_PARAMS_FILE

PROBE = r"""
import json, sys
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Odometry
from preceding_traffic.traffic_node import TrafficNode
from trust_av_common.ros.messages import time_msg
from trust_av_common.ros.spin import init_rclpy, start_node

init_rclpy(['probe', '--ros-args', '--params-file', sys.argv[1]])
node = start_node(TrafficNode)
published = []
publish_step = node.publish_step
node.publish_step = lambda step: (published.append(step), publish_step(step))


def complete(step):
    # The step's outputs as the other nodes publish them: odometry stamped at its end.
    for name, cls, offset in (('ego', Odometry, 1), ('human', Odometry, 1),
                              ('trust', Vector3Stamped, 0), ('status', DiagnosticArray, 0),
                              ('driver', DiagnosticArray, 0)):
        msg = cls()
        msg.header.stamp = time_msg(node.stamp(step + offset))
        node.on_done(name, msg, offset)


node.on_start(None)
complete(0)
running = list(published)
node.stopping = True        # what spin_node sets on SIGINT/SIGTERM before it drains
complete(1)
print(json.dumps({'running': running, 'stopping': published[len(running):],
                  'done': node.done}))
node.close()
node.destroy_node()
"""


def test_a_stop_request_ends_the_chain_at_the_step_in_progress(tmp_path: Path,
                                                              ros_domain: str) -> None:
    env = dict(os.environ, ROS_DOMAIN_ID=ros_domain, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_LOG_DIR=str(tmp_path / 'ros_log'))
    proc = subprocess.run([sys.executable, '-c', PROBE, str(DEFAULT_PARAMS_FILE)],
                          capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result['running'] == [0, 1]      # step 0 complete: step 1 starts
    assert result['stopping'] == []         # step 1 complete after the request: no step 2
    assert result['done'] is True
