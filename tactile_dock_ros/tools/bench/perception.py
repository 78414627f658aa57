"""640x480 depth image -> slice -> prior: decode, slice, prior assembly and occlusion sampler.

Each terrain of ``perception.scenes`` is rendered once (16UC1 bytes, noise on, no calibration
error); then each stage is timed ``--repeats`` times and the median reported next to its target
(slice <= 20 ms, whole prior <= 200 ms on one core) as a ratio. The prior's 2-sigma
coverage of the true terrain is reported as a quality check.
"""

from __future__ import annotations

import time

import numpy as np

from ...perception import evaluation, scenes
from ...perception.bridge import sample_truncated_gaussian
from ...perception.config import Extrinsic, PerceptionConfig
from ...perception.depth import decode_depth, encode_depth
from ...perception.render import render_depth
from ...perception.slicing import extract_slice
from ...perception.terrain_prior import build_prior

TARGET_SLICE_S = 0.020
TARGET_TOTAL_S = 0.200


def add_arguments(parser) -> None:
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument(
        "--terrains", nargs="+", default=sorted(scenes.TERRAINS), choices=sorted(scenes.TERRAINS)
    )


def _one_run(data: bytes, step: int, K, config: PerceptionConfig, args, seed: int):
    """Stage times (seconds) of one decode -> slice -> prior pass, with the slice and prior."""
    sampler_s = 0.0

    def sampler(*sampler_args):
        nonlocal sampler_s
        start = time.perf_counter()
        out = sample_truncated_gaussian(*sampler_args)
        sampler_s += time.perf_counter() - start
        return out

    t0 = time.perf_counter()
    depth = decode_depth(data, args.height, args.width, "16UC1", False, step)
    t1 = time.perf_counter()
    sl = extract_slice(
        depth, K, config.extrinsic, config.slice, config.occlusion.max_hidden_vertices
    )
    t2 = time.perf_counter()
    prior = build_prior(
        sl,
        config.extrinsic,
        config.depth_noise,
        config.occlusion,
        config.friction,
        np.random.default_rng(seed),
        sampler,
    )
    t3 = time.perf_counter()
    times = {
        "decode": t1 - t0,
        "slice": t2 - t1,
        "assembly": t3 - t2 - sampler_s,
        "sampler": sampler_s,
        "total": t3 - t0,
    }
    return times, sl, prior


def run(args) -> dict:
    K, T = scenes.default_camera(args.width, args.height)
    config = PerceptionConfig(Extrinsic.from_sigmas(T, 0.01, np.deg2rad(1.5)))
    rows = []
    header = f"{'terrain':<18}{'decode':>9}{'slice':>9}{'assembly':>10}{'sampler':>9}{'total':>9}"
    print(header + "   ms (median)  n  hidden  coverage")
    for name in args.terrains:
        terrain = scenes.TERRAINS[name]()
        rng = np.random.default_rng(args.seed)
        depth = render_depth(terrain, K, T, (args.width, args.height), rng, config.depth_noise)
        data, step = encode_depth(depth, "16UC1")
        times = {"decode": [], "slice": [], "assembly": [], "sampler": [], "total": []}
        for rep in range(args.repeats):
            one, sl, prior = _one_run(data, step, K, config, args, args.seed + rep)
            for key, value in one.items():
                times[key].append(value)
        med = {k: float(np.median(v)) for k, v in times.items()}
        cov, _ = evaluation.coverage(prior, terrain, sl.camera_xy, config.slice.vertex_spacing_m)
        row = {
            "terrain": name,
            "median_s": med,
            "all_s": times,
            "slice_over_target": med["slice"] / TARGET_SLICE_S,
            "total_over_target": med["total"] / TARGET_TOTAL_S,
            "vertices": int(prior.n_vertices),
            "basis_columns": int(prior.n_basis),
            "hidden_stretches": len(sl.stretches),
            "coverage_2sigma": cov,
        }
        rows.append(row)
        ms = [1e3 * med[k] for k in ("decode", "slice", "assembly", "sampler", "total")]
        print(
            f"{name:<18}" + "".join(f"{m:9.1f}" for m in ms[:3]) + f"{ms[3]:9.1f}{ms[4]:9.1f}"
            f"   {prior.n_vertices:>13} {len(sl.stretches):>6} {cov:9.3f}"
        )
    print(
        f"targets: slice {TARGET_SLICE_S * 1e3:.0f} ms, whole prior {TARGET_TOTAL_S * 1e3:.0f} ms"
    )
    return {
        "image": [args.width, args.height],
        "targets_s": {"slice": TARGET_SLICE_S, "total": TARGET_TOTAL_S},
        "rows": rows,
        "note": "wall-clock on a machine shared with other jobs; median over --repeats",
    }
