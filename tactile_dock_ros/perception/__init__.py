"""Depth image to 2D terrain slice to Gaussian shape prior; ROS-free."""
