"""Render one exploration episode to PNG, one panel per cycle (like the paper's Fig. 3).

    python -m tactile_dock_ros.tools.plot --problem three_ledges --truth-seed 0 --out ep.png

Posterior samples in grey, the ground truth in black, history segments coloured by status
(free, collide, stick, slip left, slip right), the executed paths in blue (the current one bold)
and the chosen docking site with its P_dock in each panel's title.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..core import explore, problems
from . import figures


def render(problem, truth: np.ndarray, result: explore.EpisodeResult, out: Path) -> None:
    """Write a PNG of ``result`` (one panel per cycle, at most 6 shown: first and last ones)."""
    plt = figures.pyplot()
    log = result.cycles_log
    shown = log if len(log) <= 6 else [*log[:3], *log[-3:]]
    cols = max(1, min(3, len(shown)))
    rows = max(1, int(np.ceil(len(shown) / cols)))
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 4.5 * rows), squeeze=False)
    closed = problem.prior.closed
    history = result.history
    for ax in axes.ravel()[len(shown) :]:
        ax.axis("off")
    for ax, entry in zip(axes.ravel(), shown, strict=False):
        for verts in entry.samples:
            figures.outline(ax, verts, closed, color="0.6", lw=0.5, alpha=0.5)
        figures.outline(ax, truth, closed, color="k", lw=1.5)
        # what the robot had felt when it planned this cycle
        figures.history(ax, history.subset(np.arange(entry.history_length)))
        executed = [c.plan.path for c in log[: entry.cycle] if c.plan.decision == "dock"]
        for path in executed:
            ax.plot(*path.T, color="tab:blue", lw=0.8, alpha=0.6)
        plan = entry.plan
        if plan.decision == "dock":
            ax.plot(*plan.path.T, color="tab:blue", lw=2.0)
            ax.plot(*plan.target_point, "o", mfc="none", mec="tab:blue", ms=9)
            outcome = "docked" if entry.docked else ("contact" if entry.contact else "no contact")
            title = f"cycle {entry.cycle + 1}: edge {plan.target_edge}, P_dock {plan.p_dock:.2f}"
            ax.set_title(f"{title}\n-> {outcome}", fontsize=9)
        else:
            ax.set_title(f"cycle {entry.cycle + 1}: give up\n{plan.reason[:60]}", fontsize=9)
        ax.plot(*problem.start, "k.", ms=8)
        ax.set_aspect("equal")
    fig.suptitle(f"{problem.name}: {result.outcome} after {result.cycles} moves", fontsize=11)
    fig.tight_layout()
    figures.save(fig, out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tactile_dock_ros.tools.plot", description=__doc__
    )
    parser.add_argument("--problem", default="three_ledges", choices=problems.names())
    parser.add_argument("--truth-seed", type=int, default=0, help="seed of the ground truth")
    parser.add_argument("--seed", type=int, default=1, help="seed of the episode")
    parser.add_argument("--strategy", default="ours", choices=explore.STRATEGIES)
    parser.add_argument("--max-cycles", type=int, default=15)
    parser.add_argument("--out", type=Path, required=True, help="PNG file to write")
    args = parser.parse_args(argv)
    problem = problems.get(args.problem)
    truth = problem.sample_ground_truth(np.random.default_rng(args.truth_seed))
    result = explore.run_episode(
        problem, truth, args.strategy, np.random.default_rng(args.seed), args.max_cycles
    )
    render(problem, truth, result, args.out)
    print(f"{result.outcome} after {result.cycles} moves ({result.message}); wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
