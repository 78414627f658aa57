"""RViz markers (visualization_msgs/MarkerArray) for shapes, samples, history and plans."""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Pose, Quaternion, Vector3
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from tactile_dock_ros.core.history import STATUS_RGBA, History, Status
from tactile_dock_ros.nodes.convert import plane_point


def _strip(header: Header, ns: str, index: int, points, rgba, width: float = 0.003) -> Marker:
    return Marker(
        header=header,
        ns=ns,
        id=index,
        type=Marker.LINE_STRIP,
        action=Marker.ADD,
        points=[plane_point(xy) for xy in points],
        color=ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]),
        scale=Vector3(x=width, y=width, z=width),
        pose=Pose(orientation=Quaternion(w=1.0)),
    )


def polylines(header: Header, ns: str, vertices: np.ndarray, rgba) -> list[Marker]:
    """One line strip per polyline in ``vertices`` (k, n, 2)."""
    return [_strip(header, ns, i, v, rgba, 0.002) for i, v in enumerate(vertices)]


def history(header: Header, observed: History) -> list[Marker]:
    return [
        _strip(header, "history", i, [a, b], STATUS_RGBA[Status(s)], 0.005)
        for i, (a, b, s) in enumerate(zip(observed.a, observed.b, observed.status, strict=True))
    ]


def samples_and_history(vertices: np.ndarray, observed: History, header: Header) -> MarkerArray:
    clear = Marker(header=header, action=Marker.DELETEALL)
    samples = polylines(header, "samples", vertices, (0.2, 0.4, 1.0, 0.3))
    return MarkerArray(markers=[clear, *samples, *history(header, observed)])
