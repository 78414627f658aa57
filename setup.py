"""`pip install .` gives the ROS-free library (no rclpy, no messages).

The ROS 2 package itself is built by CMakeLists.txt (colcon / ament_cmake): that build generates
the messages and installs everything, nodes included. This file serves users who want the method
(core, perception, execution) and its ROS-free tools (bench sampling / probsim / docking /
perception, plot, calibrate, fit_surface_prior) in a plain Python environment, e.g. for offline
analysis. The ROS tools in the same folder (demo, episode, bag, replay, bench episode) need a
ROS 2 environment.
"""

from setuptools import setup

setup(
    name="tactile_dock_ros",
    version="0.1.0",
    description="Bayesian tactile exploration for compliant docking (ROS-free core library)",
    license="Apache-2.0",
    python_requires=">=3.10",
    packages=[
        "tactile_dock_ros",
        "tactile_dock_ros.core",
        "tactile_dock_ros.execution",
        "tactile_dock_ros.perception",
        "tactile_dock_ros.tools",
        "tactile_dock_ros.tools.bench",
    ],
    install_requires=["numpy>=1.26", "numba>=0.59", "scipy>=1.11", "shapely>=2.0", "pyyaml>=6.0"],
    extras_require={
        "perception": ["opencv-contrib-python-headless>=4.9"],
        "plot": ["matplotlib>=3.8"],
        "bench": ["tmg-hmc>=1.0.4"],
    },
)
