"""Matplotlib drawing shared by the episode figures (tools.plot, tools.episode, tools.replay).

History segments take ``core.history.STATUS_RGBA``, the colours of the RViz markers
(``nodes.markers``), so a figure and RViz show a history alike.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.history import STATUS_RGBA, History, Status


def pyplot():
    """matplotlib.pyplot on the file-only Agg backend (no display on robots and CI)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def outline(ax, vertices: np.ndarray, closed: bool, *fmt: str, **style) -> None:
    """A shape's (n, 2) vertices as a polyline, closed back to the first vertex if ``closed``."""
    ring = np.vstack([vertices, vertices[:1]]) if closed else np.asarray(vertices)
    ax.plot(*ring.T, *fmt, **style)


def history(ax, observed: History, width: float = 2.5) -> None:
    """Observation segments coloured by status."""
    for a, b, s in zip(observed.a, observed.b, observed.status, strict=True):
        ax.plot([a[0], b[0]], [a[1], b[1]], color=STATUS_RGBA[Status(s)], lw=width)


def save(fig, path, dpi: int = 90) -> None:
    """Write the figure (creating the folder) and release it."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    pyplot().close(fig)
