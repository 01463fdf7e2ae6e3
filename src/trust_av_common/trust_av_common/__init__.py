"""The shared floor of every trust-av package (as nav2_util is Nav2's): its top-level
modules are pure Python (numpy, CasADi settings, PyYAML), no rclpy and no message types;
:mod:`trust_av_common.ros` holds the rclpy helpers of every node.

- :mod:`~trust_av_common.errors`: :class:`~trust_av_common.errors.TrustAvError`, the one
  exception base of the project, and the one-line message helpers.
- :mod:`~trust_av_common.registry`: the plug-in groups (entry points) and their components.

- :mod:`~trust_av_common.params`: configuration dataclasses whose fields carry their
  description, unit and range (one place per parameter).
- :mod:`~trust_av_common.param_layers`: ROS 2 params files in layers over the shipped
  one, read by rcl's rules (:mod:`~trust_av_common.rcl_yaml`,
  :mod:`~trust_av_common.rcl_values`).
- :mod:`~trust_av_common.kinematics`: longitudinal vehicle dynamics shared by every
  vehicle model (the AV's NMPC, the human's MPC, the simulated plants).
- :mod:`~trust_av_common.solver`: CasADi solver settings of the small MPCs.
- :mod:`~trust_av_common.topics`: the node graph's topic table.
- :mod:`~trust_av_common.lockstep`: stamps and the step buffer of the lock-step protocol.
- :mod:`~trust_av_common.wall_clock`: real-vehicle (wall-clock) mode.
- :mod:`~trust_av_common.output_files`: results written whole or not at all.
- :mod:`~trust_av_common.moved`: the warn-aliases of the modules that moved here.
"""

__all__: list[str] = []

