"""The adapters' topics and QoS profiles (rclpy), shared by the two adapter nodes."""

__all__: list[str] = []
