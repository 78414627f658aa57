"""QoS profiles shared by the nodes (one meaning each).

* ``SENSOR``: sensor streams (depth image, F/T wrench, tool pose): best effort, keep last 5 —
  a best-effort subscription also matches a reliable driver.
* ``LATCHED``: state that a late joiner must see (prior, contact history, samples, episode
  status): reliable, transient local, keep last 1.
* ``EVENTS``: plans and execution reports: reliable, volatile, keep last 100 (each is handled
  once; a burst of plans, and of their refusal reports, must not push out the first of them:
  with 10, a loaded executor lost the running plan, ``bench safety --parts load``).
* ``COMMAND``: Cartesian commands to the arm: reliable (matches reliable and best-effort
  drivers), keep last 1 (only the newest command matters).
"""

from rclpy.qos import (
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

SENSOR = qos_profile_sensor_data
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
EVENTS = QoSProfile(
    depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE
)
COMMAND = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE
)
