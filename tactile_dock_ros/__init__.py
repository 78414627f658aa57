"""Bayesian tactile exploration for compliant docking (K. Hauser), as a ROS 2 package.

Subpackages: ``core`` (the method, ROS-free), ``perception`` (depth image to shape prior,
ROS-free), ``nodes`` (rclpy nodes), ``tools`` (command-line tools) and ``msg`` (generated
interfaces).

The package path is extended over every ``tactile_dock_ros`` directory on ``sys.path``: in a
source checkout the hand-written modules come from the work tree while the generated ``msg``
subpackage and its typesupport libraries come from the installed copy, so edits to the Python
sources take effect without reinstalling.
"""

from pkgutil import extend_path

__path__ = extend_path(__path__, __name__)
