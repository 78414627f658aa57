"""Depth image -> ordered 2-D terrain slice in the docking plane, with hidden stretches marked.

Steps (all numpy, one pass over the valid pixels):
1. back-project the valid pixels and move them into the plane frame with the NOMINAL extrinsic;
2. keep the band |z_plane| <= band_half_width_m;
3. seen from the camera centre projected into the plane, bin the band points by bearing (bin
   width = half a vertex spacing at the median range) and keep the median range of each bin;
   the median is the outlier filter (it rejects flying pixels and the odd wrong return, which
   is why open3d's statistical outlier removal is not needed in this hot path);
4. order the bins by DECREASING bearing: a surface facing the camera is then walked with the
   solid on the left, the orientation of ``core.shape``;
5. a jump longer than ``gap_m`` between bearing neighbours is a hidden stretch (a depth
   discontinuity: the two ends lie on one line of sight, the far one seen past the near one's
   silhouette; missing returns are treated alike). Visible runs with fewer than
   ``_MIN_RUN_BINS`` bins are flying-pixel debris and are dropped into the neighbouring gap;
6. resample each visible run at the vertex spacing and put evenly spaced placeholder vertices
   (at least 3, chord / spacing - 1 when more) on the chord of each hidden stretch (the prior
   replaces them with the Brownian-bridge mean); the spacing grows until the vertex count
   fits ``max_vertices``. Each visible vertex interpolates two bin medians with weights
   ``(1 - l, l)``; it records the effective pixel count ``1 / ((1 - l)^2 / N_a + l^2 / N_b)``
   of the bins' pixel counts N, so that the std of the vertex is the one-pixel std over
   sqrt(that count) (times the median's efficiency factor, see ``terrain_prior``).
For an extruded terrain, 3-D visibility from an off-plane camera equals 2-D visibility from its
projection, so the bearing order is exact there; for a general scene it is the usual
single-viewpoint approximation.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from .config import Extrinsic, PerceptionError, SliceParams
from .geometry import arc_length, resample_polyline

_MIN_RUN_BINS = 3
_MIN_HIDDEN_VERTICES = 3  # a bridge needs a few vertices to bend, however short the chord
_MAX_SPACING_STEPS = 50


@dataclass(frozen=True)
class TerrainSlice:
    """A terrain profile in the plane frame (metres), solid on the left of the walking direction.

    Attributes:
        vertices: (n, 2); hidden vertices are placeholders on the chord of their stretch.
        hidden: (n,) bool, True for vertices of occluded stretches.
        stretches: (s, 2) int, the visible end vertices (first, last) bounding each hidden run.
        camera_xy: (2,) camera centre projected into the plane.
        spacing_m: vertex spacing actually used.
        points: (k, 2) the ordered per-bin median points the slice was resampled from.
        bin_pixels: (k,) int, how many pixels each of those bin medians aggregates.
        pixels: (n,) effective pixel count of each vertex (see module docstring); 0 if hidden.
    """

    vertices: np.ndarray
    hidden: np.ndarray
    stretches: np.ndarray
    camera_xy: np.ndarray
    spacing_m: float
    points: np.ndarray
    bin_pixels: np.ndarray
    pixels: np.ndarray


def band_points(depth_m: np.ndarray, K: np.ndarray, extrinsic: Extrinsic, half_width_m: float):
    """Plane-frame (x, y) of valid pixels within the band; raises PerceptionError when none.

    The plane-normal coordinate of a pixel is ``depth * (a(u) + b(v)) + t_z`` (separable in the
    pixel column and row), so the band is found with three whole-image operations and only the
    few in-band pixels are back-projected.
    """
    depth = np.asarray(depth_m, dtype=np.float32)
    if depth.ndim != 2:
        raise PerceptionError(f"depth image must be 2-D, got shape {depth.shape}")
    height, width = depth.shape
    fx, fy, cx, cy, skew = K[0, 0], K[1, 1], K[0, 2], K[1, 2], K[0, 1]
    R, t = extrinsic.rotation, extrinsic.camera_centre
    y_n = (np.arange(height) - cy) / fy  # ray = ((u - cx - skew y_n) / fx, y_n, 1)
    col = (R[2, 0] / fx * (np.arange(width) - cx)).astype(np.float32)
    row = (R[2, 0] * -skew * y_n / fx + R[2, 1] * y_n + R[2, 2]).astype(np.float32)
    with np.errstate(invalid="ignore"):
        z_plane = depth * (row[:, None] + col[None, :]) + np.float32(t[2])
        keep = np.abs(z_plane) <= half_width_m
        keep &= depth > 0
    v, u = np.nonzero(keep)
    if v.size == 0:
        if not np.any(np.isfinite(depth) & (depth > 0)):
            raise PerceptionError("depth image has no valid pixel")
        raise PerceptionError(
            "no depth point lies within the band of the docking plane: the plane misses the "
            "image (check T_plane_camera)"
        )
    z = depth[v, u].astype(float)
    cam = np.stack([(u - cx - skew * y_n[v]) / fx * z, y_n[v] * z, z], axis=1)
    return cam @ R[:2].T + t[:2]


def profile_from_points(
    points: np.ndarray, camera_xy: np.ndarray, spacing_m: float, jump_m: float = np.inf
):
    """Per-bearing-bin median points (k, 2), ordered by decreasing bearing, and pixel counts.

    Each bin's point lies at the bin's mean bearing; its range is the median of the pixels'
    ranges moved to that bearing along the bin's least-squares range-vs-bearing slope. On a
    surface slanted to the rays the range changes across the bin by more than the depth noise,
    and the plain median range, paired with the mean bearing, would be off the surface by a
    bias that no pixel count averages away. A bin whose ranges span more than ``jump_m`` holds
    a depth jump (two surfaces): a line through it means nothing, so it keeps the plain median.
    """
    rel = points - camera_xy
    ref = rel.mean(axis=0)
    ref = ref / max(np.linalg.norm(ref), 1e-12)
    bearing = np.arctan2(ref[0] * rel[:, 1] - ref[1] * rel[:, 0], rel @ ref)
    rng = np.linalg.norm(rel, axis=1)
    bin_width = spacing_m / (2.0 * max(np.median(rng), 1e-6))
    bins = np.floor(bearing / bin_width).astype(np.int64)
    order = np.argsort(-bins, kind="stable")  # decreasing bearing
    bins, rng, bearing = bins[order], rng[order], bearing[order]
    starts = np.flatnonzero(np.r_[True, bins[1:] != bins[:-1]])
    counts = np.diff(np.r_[starts, bins.size])
    member = np.repeat(np.arange(len(starts)), counts)
    mean_bearing = np.add.reduceat(bearing, starts) / counts
    d_bearing = bearing - mean_bearing[member]
    d_range = rng - (np.add.reduceat(rng, starts) / counts)[member]
    spread = np.add.reduceat(d_bearing**2, starts)
    slope = np.add.reduceat(d_bearing * d_range, starts) / np.maximum(spread, 1e-300)
    span = np.maximum.reduceat(rng, starts) - np.minimum.reduceat(rng, starts)
    slope = np.where((spread > 0) & (span <= jump_m), slope, 0.0)
    at_mean = rng - slope[member] * d_bearing
    at_mean = at_mean[np.lexsort((at_mean, member))]  # sorted inside each bin
    med_range = at_mean[starts + (counts - 1) // 2]
    c, s = np.cos(mean_bearing), np.sin(mean_bearing)
    dirs = np.stack([c * ref[0] - s * ref[1], s * ref[0] + c * ref[1]], axis=1)
    return camera_xy + med_range[:, None] * dirs, counts


def resample_run(run: np.ndarray, pixels: np.ndarray, count: int):
    """``count`` vertices evenly spaced along a run of bin medians, and their effective pixel
    counts ``1 / ((1 - l)^2 / N_a + l^2 / N_b)`` (the variance of a linear interpolation)."""
    s = arc_length(run)
    t = np.linspace(0.0, s[-1], count)
    frac = np.interp(t, s, np.arange(len(run), dtype=float))
    a = np.minimum(np.floor(frac).astype(int), len(run) - 2)
    lam = frac - a
    inv = (1 - lam) ** 2 / pixels[a] + lam**2 / pixels[a + 1]
    return resample_polyline(run, count), 1.0 / inv


def _layout(runs: list[np.ndarray], spacing: float, max_hidden: int):
    """Vertex counts of each visible run and of each hidden stretch between runs."""
    run_counts = [max(2, round(arc_length(r)[-1] / spacing) + 1) for r in runs]
    chords = [np.linalg.norm(b[0] - a[-1]) for a, b in itertools.pairwise(runs)]
    low = min(_MIN_HIDDEN_VERTICES, max_hidden)
    hidden_counts = [int(np.clip(round(c / spacing) - 1, low, max_hidden)) for c in chords]
    return run_counts, hidden_counts


def extract_slice(
    depth_m: np.ndarray,
    K: np.ndarray,
    extrinsic: Extrinsic,
    params: SliceParams,
    max_hidden_vertices: int = 30,
) -> TerrainSlice:
    """Depth image (metres, NaN invalid) -> TerrainSlice; PerceptionError if it cannot."""
    pts = band_points(depth_m, np.asarray(K, float), extrinsic, params.band_half_width_m)
    if len(pts) < params.min_points:
        raise PerceptionError(
            f"only {len(pts)} depth points lie in the plane's band; need {params.min_points}"
        )
    camera_xy = extrinsic.camera_centre[:2].copy()
    profile, bin_pixels = profile_from_points(pts, camera_xy, params.vertex_spacing_m, params.gap_m)
    cut = np.flatnonzero(np.linalg.norm(np.diff(profile, axis=0), axis=1) > params.gap_m) + 1
    bounds = np.r_[0, cut, len(profile)]
    kept = [(a, b) for a, b in itertools.pairwise(bounds) if b - a >= _MIN_RUN_BINS]
    runs = [profile[a:b] for a, b in kept]
    if not runs or sum(len(r) for r in runs) < 2:
        raise PerceptionError("the slice has too few visible points to form a terrain profile")
    spacing = params.vertex_spacing_m
    for _ in range(_MAX_SPACING_STEPS):
        run_counts, hidden_counts = _layout(runs, spacing, max_hidden_vertices)
        total = sum(run_counts) + sum(hidden_counts)
        if total <= params.max_vertices:
            break
        spacing *= 1.05 * total / params.max_vertices
    else:
        raise PerceptionError(f"cannot fit the slice into max_vertices={params.max_vertices}")
    pieces, hidden, pixels, stretches, n = [], [], [], [], 0
    for i, ((lo, hi), count) in enumerate(zip(kept, run_counts, strict=True)):
        if i > 0:
            a, b, k = pieces[-1][-1], profile[lo], hidden_counts[i - 1]
            frac = np.arange(1, k + 1)[:, None] / (k + 1)
            pieces.append(a + frac * (b - a))
            hidden.append(np.ones(k, bool))
            pixels.append(np.zeros(k))
            stretches.append((n - 1, n + k))
            n += k
        verts, run_pixels = resample_run(profile[lo:hi], bin_pixels[lo:hi], count)
        pieces.append(verts)
        pixels.append(run_pixels)
        hidden.append(np.zeros(count, bool))
        n += count
    return TerrainSlice(
        vertices=np.vstack(pieces),
        hidden=np.concatenate(hidden),
        stretches=np.array(stretches, dtype=int).reshape(-1, 2),
        camera_xy=camera_xy,
        spacing_m=float(spacing),
        points=profile,
        bin_pixels=bin_pixels,
        pixels=np.concatenate(pixels),
    )
