"""The shared floor of the four packages: pure Python (numpy, CasADi settings, PyYAML), no
rclpy and no message types.

- :mod:`~trust_monitor.common.params`: configuration dataclasses whose fields carry their
  description, unit and range (one place per parameter).
- :mod:`~trust_monitor.common.param_layers`: ROS 2 params files in layers over the shipped
  one, read by rcl's rules (:mod:`~trust_monitor.common.rcl_yaml`,
  :mod:`~trust_monitor.common.rcl_values`).
- :mod:`~trust_monitor.common.kinematics`: longitudinal vehicle dynamics shared by every
  vehicle model (the AV's NMPC, the human's MPC, the simulated plants).
- :mod:`~trust_monitor.common.solver`: CasADi solver settings of the small MPCs.
- :mod:`~trust_monitor.common.topics`: the node graph's topic table.
- :mod:`~trust_monitor.common.lockstep`: stamps and the step buffer of the lock-step protocol.
- :mod:`~trust_monitor.common.wall_clock`: real-vehicle (wall-clock) mode.
"""
