"""Fit the surface model's bend and corner threshold from recorded depth scans (empirical Bayes).

    python -m tactile_dock_ros.tools.fit_surface_prior SCANS \\
        --config config/perception_robot.yaml --out perception_fitted.yaml \\
        [--K fx 0 cx 0 fy cy 0 0 1] [--summary fit.json]
    python -m tactile_dock_ros.tools.fit_surface_prior /tmp/scans \\
        --config config/perception_mock.yaml --render-training 210 --seed 0 \\
        --out /tmp/perception_mock_fitted.yaml

``SCANS`` is a folder of depth images of the docking plane, all from the camera pose of
``--config``: ``*.png`` 16UC1 (millimetres, 0 = no return, as ``image_rect`` of a depth camera
saves) and/or ``*.npy`` 2-D float metres (NaN or 0 = no return). Intrinsics: ``--K`` (CameraInfo
K, row-major), else ``SCANS/camera_info.yaml`` (the ROS camera_calibration format:
``image_width``, ``image_height``, ``camera_matrix.data``). Each image goes through the
perception's own slicing (``perception.slicing``) with the config's extrinsic, depth noise and
slice settings; ``perception.surface_fit`` fits a spike-and-slab model of the slices' turns to
their second differences (no ground truth) and projects it onto ``surface.bend_sigma_rad`` and
``surface.corner_threshold``. ``--out`` is ``--config`` with those two values replaced (every
other key copied; comments are not kept) and loads with ``PerceptionConfig.load``; the summary
(``--summary``, default ``--out`` with ``.json``) holds the scans used and skipped, the fitted
model, the fitted values and the scores of the config's values and of the fitted ones.

Try it without a robot: ``--render-training N --seed S`` first renders N training scenes into
``SCANS`` (created; must hold no scans yet) with the mock camera (320x240 px, focal 262.5 px)
at the config's extrinsic displaced by a calibration error drawn from its covariance: random
walls (``scenes.random_terrain``) and the benchmark problems' truths, 5 to 2 as in ``bench
prior``, drawn from the TRAIN seed stream (``tools.bench.splits``), as 16UC1 PNGs with a
``camera_info.yaml``. Without ``--out`` it stops there.

Bad input (no scans, an unreadable image, a size that differs from the intrinsics or the other
images, a bad config or K) exits with status 2 and a message; a scan the slicing rejects (too few
points in the band) is skipped and listed in the summary.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import yaml

from ..perception import surface_fit
from ..perception.config import PerceptionConfig, PerceptionError
from ..perception.slicing import extract_slice
from .depth_scans import (
    CAMERA_INFO,
    InputError,
    depth_images,
    intrinsics,
    render_training,
    scan_files,
)

FEW_ROWS = 1000  # fewer second differences: the fit is uncertain (a warning, not an error)


def _load_config(path: Path) -> tuple[dict, PerceptionConfig]:
    """The YAML document as read, and the config it holds."""
    try:
        document = yaml.safe_load(path.read_text())
        config = PerceptionConfig.load(path)
    except (OSError, yaml.YAMLError, PerceptionError, TypeError, ValueError) as err:
        raise InputError(f"--config {path}: {err}") from None
    if config.surface.depth_model != "correlated":
        raise InputError(
            f"--config {path}: surface.depth_model is {config.surface.depth_model!r}; the fitted "
            "bend_sigma_rad and corner_threshold belong to the correlated model"
        )
    return document, config


def collect_runs(files, K, size, config: PerceptionConfig):
    """(runs, used file names, skipped [{file, error}]) of the scans."""
    runs, used, skipped = [], [], []
    for path, depth in depth_images(files, K, size, config):
        try:
            terrain = extract_slice(
                depth, K, config.extrinsic, config.slice, config.occlusion.max_hidden_vertices
            )
        except PerceptionError as err:
            skipped.append({"file": path.name, "error": str(err)})
            continue
        found = surface_fit.slice_runs(
            terrain, config.extrinsic, config.depth_noise, config.surface
        )
        if not found:
            skipped.append({"file": path.name, "error": "no visible run of 3 or more vertices"})
            continue
        runs += found
        used.append(path.name)
    return runs, used, skipped


def write_config(document: dict, fit: surface_fit.SurfaceFit, out: Path, source: Path) -> None:
    section = document["perception"] if "perception" in document else document
    surface = dict(section.get("surface") or {})
    surface["bend_sigma_rad"] = float(f"{fit.bend_sigma_rad:.4g}")
    surface["corner_threshold"] = float(f"{fit.corner_threshold:.4g}")
    section["surface"] = surface
    header = (
        f"# {source} with surface.bend_sigma_rad and surface.corner_threshold fitted by\n"
        f"# python -m tactile_dock_ros.tools.fit_surface_prior ({fit.runs} runs, {fit.rows} "
        "second differences)\n"
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(header + yaml.safe_dump(document, sort_keys=False))
    PerceptionConfig.load(out)  # what the perception node will load


def run(args) -> dict | None:
    document, config = _load_config(args.config)
    if args.render_training:
        written = render_training(args.scans, args.render_training, args.seed, config)
        print(f"rendered {len(written)} training scans (seed {args.seed}) into {args.scans}")
        if args.out is None:
            return None
    if args.out is None:
        raise InputError("--out is required to fit (only --render-training runs without it)")
    files = scan_files(args.scans)
    if not files:
        raise InputError(f"{args.scans}: no *.png or *.npy depth images")
    K, size = intrinsics(args.scans, args.K)
    try:
        runs, used, skipped = collect_runs(files, K, size, config)
    except PerceptionError as err:  # check_intrinsics against the first image, decoding
        raise InputError(str(err)) from None
    if not runs:
        raise InputError(
            f"none of the {len(files)} scans gave a slice (see the errors: {skipped[:3]})"
        )
    fit = surface_fit.fit_surface(runs, config.surface)
    write_config(document, fit, args.out, args.config)
    summary = {
        "scans": str(args.scans),
        "config": str(args.config),
        "out": str(args.out),
        "K": np.asarray(K).tolist(),
        "scans_found": len(files),
        "scans_used": len(used),
        "skipped": skipped,
        **fit.to_dict(),
    }
    mix = fit.mixture.mixture
    print(
        f"{len(used)} of {len(files)} scans used ({len(skipped)} skipped): {fit.runs} runs, "
        f"{fit.rows} second differences"
    )
    print(
        f"fitted model: face bend {mix.bend_sigma_rad:.4f} rad, corners {mix.corner_fraction:.3f} "
        f"of vertices with turn std {mix.corner_sigma_rad:.3f} rad, "
        f"noise scale {mix.noise_scale:.3f}"
        + (f" (on bounds: {', '.join(fit.mixture.at_bounds)})" if fit.mixture.at_bounds else "")
    )
    print(
        f"bend_sigma_rad {config.surface.bend_sigma_rad} -> {fit.bend_sigma_rad:.4f}, "
        f"corner_threshold {config.surface.corner_threshold} -> {fit.corner_threshold:.3f}; "
        f"expected log score per row {fit.score['before']:.3f} -> {fit.score['after']:.3f}, "
        f"smoother log evidence {fit.smoother_evidence['before']:.1f} -> "
        f"{fit.smoother_evidence['after']:.1f}"
    )
    if fit.rows < FEW_ROWS:
        summary["warning"] = (
            f"only {fit.rows} second differences (fewer than {FEW_ROWS}): the fitted values are "
            "uncertain; record more scans"
        )
        print(f"warning: {summary['warning']}", file=sys.stderr)
    summary_path = args.summary or args.out.with_suffix(".json")
    summary_path.parent.mkdir(parents=True, exist_ok=True)
    summary_path.write_text(json.dumps(summary, indent=2))
    print(f"wrote {args.out} and {summary_path}")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tactile_dock_ros.tools.fit_surface_prior",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="The model and the decision: tactile_dock_ros/perception/surface_fit.py, "
        "docs/perception.md.",
    )
    parser.add_argument("scans", type=Path, help="folder of depth images (*.png 16UC1 mm, *.npy m)")
    parser.add_argument(
        "--config",
        type=Path,
        required=True,
        help="perception config YAML the scans were taken with",
    )
    parser.add_argument("--out", type=Path, help="perception config YAML to write (fitted surface)")
    parser.add_argument("--summary", type=Path, help="summary JSON (default: --out with .json)")
    parser.add_argument(
        "--K", type=float, nargs=9, help=f"CameraInfo K, row-major (default: SCANS/{CAMERA_INFO})"
    )
    parser.add_argument(
        "--render-training",
        type=int,
        default=0,
        metavar="N",
        help="first render N training scenes of the mock camera into SCANS (see the docstring)",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of --render-training (train split)"
    )
    args = parser.parse_args(argv)
    if args.render_training < 0:
        parser.error("--render-training must be >= 0")
    try:
        run(args)
    except InputError as err:
        print(f"fit_surface_prior: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
