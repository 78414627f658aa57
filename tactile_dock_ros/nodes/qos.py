"""QoS profiles shared by the nodes (one meaning each).

* ``SENSOR``: sensor streams (depth image, F/T wrench, tool pose): best effort, keep last 5 —
  a best-effort subscription also matches a reliable driver.
* ``LATCHED``: state that a late joiner must see (contact history, samples, episode status):
  reliable, transient local, keep last 1.
* ``priors(max_holds)``: ``terrain_prior``: as ``LATCHED`` but keep last ``max_holds`` (the
  holds perception keeps), so a node that (re)starts after several captures receives every kept
  hold, oldest first, ending on the latest, and can dock on (or resume an episode on) any of
  them. Perception, planner and inference pass their own ``max_holds`` parameter, tools its
  default; depth is no QoS compatibility policy, so any two depths match. Decision: the
  publisher's depth is ``max_holds``, not the parameter's upper bound: a late joiner then gets
  no hold perception dropped, and perception retains no more priors than it keeps.
* ``EVENTS``: plans: reliable, volatile, keep last 100 (each is handled once; the planner resends
  the plan being executed every 0.5 s; a burst of plans must not push out the first of them:
  with 10, a loaded executor lost the running plan, ``bench safety --parts load``).
* ``REPORTS``: execution reports: reliable, transient local, keep last ``REPORT_DEPTH``: a node
  restarted mid-episode (inference, planner) receives the reports it missed; receivers drop
  duplicates by (episode, plan id). Volatile subscribers (``ros2 topic echo``) match too.
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


def priors(max_holds: int) -> QoSProfile:
    """The ``terrain_prior`` profile keeping the last ``max_holds`` priors."""
    return QoSProfile(
        depth=max_holds,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


EVENTS = QoSProfile(
    depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE
)
REPORT_DEPTH = 32  # more than the reports of one episode sent while a node restarts
REPORTS = QoSProfile(
    depth=REPORT_DEPTH,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
COMMAND = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE
)
