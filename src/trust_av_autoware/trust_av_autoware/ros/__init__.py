"""The adapters' topics and QoS profiles (rclpy), shared by the two adapter nodes."""
