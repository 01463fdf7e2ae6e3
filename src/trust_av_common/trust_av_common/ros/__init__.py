"""rclpy helpers shared by every node of the graph (the only place besides the nodes and the
graph orchestration that imports rclpy or message packages).

- :mod:`~trust_av_common.ros.qos`: the named QoS profiles.
- :mod:`~trust_av_common.ros.parameters`: declare a configuration dataclass as ROS parameters.
- :mod:`~trust_av_common.ros.messages`: message builders and readers.
- :mod:`~trust_av_common.ros.spin`: a node's main loop (init, spin, shutdown) and the
  wall-clock control loop.
"""

__all__: list[str] = []

