"""Fit the learned terrain prior's class library from training truths.

    python -m tactile_dock_ros.tools.fit_terrain_classes --out config/terrain_classes.npz \\
        [--per-class 400] [--seed 0] [--variance-kept 0.999] [--floor-mm 0.3]

One class per benchmark problem (``core.problems``): ``--per-class`` truths drawn from the
problem's truth sampler on the TRAIN split (``tools.bench.splits``) with their own sub-stream
``[*split_seed("train", seed), 99, class_index, i]``. ``bench docking`` draws its train truths
from ``[seed, problem_index, ...]`` (problem index < 99) and its test truths from the test split,
so no benchmark truth is ever a training truth. Each class is a PCA Gaussian
(``perception.learned_prior.fit_class``) with the problem's closedness and friction. The
library is written to ``--out`` (``TerrainLibrary.save``) and a summary per class (vertices, PCA
directions kept, floor, total std) is printed. Bad arguments exit with status 2 and a message.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..core import problems
from ..perception.learned_prior import FLOOR_M, TerrainLibrary, fit_class
from .bench.splits import MAX_SEED, split_seed

SUB_STREAM = 99  # second seed word: apart from bench docking's problem indices


def training_truths(name: str, per_class: int, seed: int) -> np.ndarray:
    """(per_class, n, 2) train truths of problem ``name`` (the library's sub-stream)."""
    index = problems.names().index(name)
    base = split_seed("train", seed)
    problem = problems.get(name)
    return np.stack(
        [
            problem.sample_ground_truth(np.random.default_rng([*base, SUB_STREAM, index, i]))
            for i in range(per_class)
        ]
    )


def fit_library(
    per_class: int = 400, seed: int = 0, variance_kept: float = 0.999, floor_m: float = FLOOR_M
) -> TerrainLibrary:
    """One class per ``core.problems`` problem, fitted on ``per_class`` training truths."""
    classes = []
    for name in problems.names():
        problem = problems.get(name)
        truths = training_truths(name, per_class, seed)
        classes.append(
            fit_class(
                name,
                truths,
                closed=problem.prior.closed,
                friction=problem.friction,
                variance_kept=variance_kept,
                floor_m=floor_m,
            )
        )
    return TerrainLibrary(tuple(classes))


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m tactile_dock_ros.tools.fit_terrain_classes",
        description=__doc__.split("\n\n")[0],
        epilog="Truths come from the train split only; the library loads with "
        "perception.learned_prior.TerrainLibrary.load and is used by "
        "'bench docking --prior learned --terrain-classes FILE'.",
    )
    parser.add_argument("--out", type=Path, required=True, help="library file to write (.npz)")
    parser.add_argument(
        "--per-class", type=int, default=400, help="training truths per class (>= 2)"
    )
    parser.add_argument("--seed", type=int, default=0, help=f"train seed, in [0, {MAX_SEED})")
    parser.add_argument(
        "--variance-kept",
        type=float,
        default=0.999,
        help="fraction of the training variance kept by the PCA, in (0, 1]",
    )
    parser.add_argument(
        "--floor-mm",
        type=float,
        default=FLOOR_M * 1000,
        help="least isotropic std per coordinate of a class, millimetres (> 0)",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.per_class < 2:
        parser.error(f"--per-class must be >= 2, got {args.per_class}")
    if not 0 <= args.seed < MAX_SEED:
        parser.error(f"--seed must be in [0, {MAX_SEED}), got {args.seed}")
    if not 0.0 < args.variance_kept <= 1.0:
        parser.error(f"--variance-kept must be in (0, 1], got {args.variance_kept}")
    if not (np.isfinite(args.floor_mm) and args.floor_mm > 0):
        parser.error(f"--floor-mm must be > 0, got {args.floor_mm}")
    if args.out.exists() and args.out.is_dir():
        parser.error(f"--out {args.out} is a directory")
    if not args.out.parent.is_dir():
        parser.error(f"--out: no such directory {args.out.parent}")
    library = fit_library(args.per_class, args.seed, args.variance_kept, args.floor_mm / 1000)
    library.save(args.out)
    print(f"{'class':13} {'vertices':>8} {'pca dirs':>8} {'floor mm':>8} {'rms std mm':>10}")
    for c in library.classes:
        floor = float(c.basis[0, -2 * c.n_vertices :].max(initial=0.0))
        pca = c.basis.shape[1] - 2 * c.n_vertices
        rms = float(np.sqrt(np.sum(c.basis**2) / c.basis.shape[0]))
        print(f"{c.name:13} {c.n_vertices:>8} {pca:>8} {floor * 1000:>8.3f} {rms * 1000:>10.2f}")
    print(f"wrote {args.out} ({args.per_class} train truths per class, seed {args.seed})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
