"""Refit the learned prior's terrain classes from depth scans of your wall (no ground truth).

    python -m tactile_dock_ros.tools.refit_terrain_classes SCANS \\
        --classes config/terrain_classes.npz --config config/perception_robot.yaml \\
        --out my_classes.npz [--K fx 0 cx 0 fy cy 0 0 1] [--iterations 4] \\
        [--init-floor-mm 10] [--min-inlier-fraction 0.9]
    python -m tactile_dock_ros.tools.refit_terrain_classes /tmp/scans \\
        --classes config/terrain_classes.npz --config config/perception_mock.yaml \\
        --render-training 140 --seed 0 --out /tmp/refit_classes.npz

``SCANS`` is a folder of depth images from the camera pose of ``--config`` (``*.png`` 16UC1 mm,
``*.npy`` float m; intrinsics from ``--K`` or ``SCANS/camera_info.yaml``; the format of
``tools.fit_surface_prior``). ``--classes`` is the starting library: it fixes the classes and
each class's vertex parametrization (the shipped one, or one ``tools.fit_terrain_classes``
fitted on drawn or CAD shapes). Each scan's slice is conditioned on every class; expectation-
maximization (``perception.class_refit``) refits each class's mean and covariance from the
scans it explains best, leaving out scans whose best class explains less than
``--min-inlier-fraction`` of the slice (walls no class describes). The out-of-library gates are
then refitted on the same scans (``prior_select.inlier_samples``: each scan with the whole
refitted library and without its class; ``prior_select.fit_thresholds``, one per class) and
stored in ``--out``, which perception loads with ``prior_source: depth terrain_classes:=...``.
Printed: the scans used and skipped, per EM step the scans assigned per class and their mean log
evidence per scan (the library of the largest is kept), and per class the gate's two samples and
the gate.

Try it without a robot: ``--render-training N --seed S`` first renders N train-split scenes into
``SCANS`` (new) with the mock camera: of every 7, 1 random wall (no class describes it) and 6
problem truths. Bad input exits with status 2 and a message.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..perception.class_refit import INIT_FLOOR_M, refit_library
from ..perception.config import PerceptionConfig, PerceptionError
from ..perception.learned_prior import TerrainLibrary, slice_rays
from ..perception.prior_select import fit_thresholds, inlier_samples
from .depth_scans import InputError, depth_images, intrinsics, render_training, scan_files
from .fit_terrain_classes import print_gates

RANDOM_PER_SEVEN = 1  # --render-training: one wall per 7 that no class describes


def run(args) -> TerrainLibrary | None:
    try:
        config = PerceptionConfig.load(args.config)
    except (OSError, PerceptionError) as err:
        raise InputError(f"--config {args.config}: {err}") from None
    try:
        library = TerrainLibrary.load(args.classes)
    except (OSError, ValueError) as err:
        raise InputError(f"--classes {args.classes}: {err}") from None
    if args.render_training:
        written = render_training(
            args.scans, args.render_training, args.seed, config, RANDOM_PER_SEVEN
        )
        print(f"rendered {len(written)} training scans (seed {args.seed}) into {args.scans}")
    files = scan_files(args.scans)
    if not files:
        raise InputError(f"{args.scans}: no *.png or *.npy depth images")
    K, size = intrinsics(args.scans, args.K)
    scans, skipped = [], []
    try:
        for path, depth in depth_images(files, K, size, config):
            try:
                scans.append(slice_rays(depth, K, config))
            except PerceptionError as err:
                skipped.append(f"{path.name}: {err}")
    except PerceptionError as err:  # the intrinsics against the first image
        raise InputError(str(err)) from None
    print(f"{len(scans)} of {len(files)} scans give a slice ({len(skipped)} skipped)", flush=True)
    if len(scans) < args.min_scans:
        raise InputError(f"{len(scans)} scans with a slice, need at least {args.min_scans}")
    refit = refit_library(
        library,
        scans,
        config,
        args.iterations,
        args.min_scans,
        args.min_inlier_fraction,
        args.init_floor_mm / 1000,
    )
    for i, step in enumerate(refit.steps):
        counts = {c.name: int(np.sum(step.assigned == k)) for k, c in enumerate(library.classes)}
        left = int(np.sum(step.assigned < 0))
        print(
            f"library after {i} iterations: scans per class {counts}, {left} left out, "
            f"mean log evidence per scan {step.log_evidence:.2f}"
            + (" (kept)" if i == refit.kept else "")
        )
    assigned = refit.steps[refit.kept].assigned
    names = [c.name for c in library.classes]
    labelled = [(r, names[k]) for r, k in zip(scans, assigned, strict=True) if k >= 0]
    if not labelled:
        raise InputError(f"no scan passed --min-inlier-fraction {args.min_inlier_fraction}")
    inside, outside = inlier_samples(refit.library, labelled, config)
    refitted = refit.library.with_gates(fit_thresholds(inside, outside))
    refitted.save(args.out)
    print_gates(refitted, inside, outside)
    print(f"wrote {args.out}")
    return refitted


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m tactile_dock_ros.tools.refit_terrain_classes",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="The method and its measurement: tactile_dock_ros/perception/class_refit.py, "
        "docs/perception.md.",
    )
    parser.add_argument("scans", type=Path, help="folder of depth images (*.png 16UC1 mm, *.npy m)")
    parser.add_argument("--classes", type=Path, required=True, help="starting library (.npz)")
    parser.add_argument(
        "--config", type=Path, required=True, help="perception config YAML of the scans' camera"
    )
    parser.add_argument("--out", type=Path, required=True, help="library to write (.npz)")
    parser.add_argument("--K", type=float, nargs=9, help="CameraInfo K, row-major")
    parser.add_argument("--iterations", type=int, default=4, help="EM iterations (>= 1)")
    parser.add_argument(
        "--init-floor-mm",
        type=float,
        default=INIT_FLOOR_M * 1000,
        help="isotropic std added to the starting classes, millimetres (>= 0)",
    )
    parser.add_argument(
        "--min-inlier-fraction",
        type=float,
        default=0.9,
        help="scans whose best class explains less of the slice are left out, in [0, 1]",
    )
    parser.add_argument(
        "--min-scans", type=int, default=5, help="scans a class needs to be refitted (>= 2)"
    )
    parser.add_argument(
        "--render-training",
        type=int,
        default=0,
        metavar="N",
        help="first render N training scenes of the mock camera into SCANS (see above)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of --render-training")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.iterations < 1:
        parser.error(f"--iterations must be >= 1, got {args.iterations}")
    if not (np.isfinite(args.init_floor_mm) and args.init_floor_mm >= 0):
        parser.error(f"--init-floor-mm must be >= 0, got {args.init_floor_mm}")
    if not 0.0 <= args.min_inlier_fraction <= 1.0:
        parser.error(f"--min-inlier-fraction must be in [0, 1], got {args.min_inlier_fraction}")
    if args.min_scans < 2:
        parser.error(f"--min-scans must be >= 2, got {args.min_scans}")
    if args.render_training < 0:
        parser.error(f"--render-training must be >= 0, got {args.render_training}")
    if args.out.is_dir() or not args.out.parent.is_dir():
        parser.error(f"--out {args.out}: not a file path in an existing directory")
    try:
        run(args)
    except InputError as err:
        print(f"refit_terrain_classes: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
