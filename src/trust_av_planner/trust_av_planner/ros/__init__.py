"""The planner node's rclpy side beyond the node module itself."""

__all__: list[str] = []
