"""RViz markers: one strip per sample, one coloured segment per history observation."""

import numpy as np
from std_msgs.msg import Header
from visualization_msgs.msg import Marker

from tactile_dock_ros.core.history import STATUS_RGBA, History, Status
from tactile_dock_ros.nodes import markers


def test_samples_and_history_markers():
    samples = np.random.default_rng(0).normal(size=(3, 5, 2))
    history = History([[0, 1], [0, 0.1]], [[0, 0.1], [0, 0.09]], [Status.FREE, Status.SLIP_LEFT])
    array = markers.samples_and_history(samples, history, Header(frame_id="dock_plane"))
    assert array.markers[0].action == Marker.DELETEALL
    strips = array.markers[1:]
    assert [m.ns for m in strips] == ["samples"] * 3 + ["history"] * 2
    assert [len(m.points) for m in strips] == [5, 5, 5, 2, 2]
    assert strips[0].points[2].x == samples[0, 2, 0]
    slip = strips[-1].color
    assert (slip.r, slip.g, slip.b) == STATUS_RGBA[Status.SLIP_LEFT][:3]
    assert len({m.id for m in strips if m.ns == "samples"}) == 3
