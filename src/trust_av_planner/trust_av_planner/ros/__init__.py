"""The planner node's rclpy side beyond the node module itself."""
