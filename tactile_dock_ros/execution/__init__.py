"""Executing docking plans, ROS-free: the plan and report types, the guarded-move state machine
and the mock arm's physics. The executor and mock_hardware nodes are the rclpy glue around it."""
