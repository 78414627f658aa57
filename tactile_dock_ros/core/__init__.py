"""The method, ROS-free: shape model, constraints, samplers, probabilistic simulation, planner."""
