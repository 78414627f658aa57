"""Sampler threads side by side: every cycle of one docking episode sampled again with each
``--threads`` count (the inference node's ``sampler_threads``), ``--repeats`` times; per cycle
the median seconds per count and its ratio to the first count's. The draws must be the same in
every count: a cycle whose draws differ fails the run (``side_by_side``: the episode, the
calls, the rotating order).

Example: ``python -m tactile_dock_ros.tools.bench threads --problem three_ledges --instance 9
--episode-seed 1 --threads 1 2 --repeats 5 --json out.json``. On a machine that runs other work,
counts above its free cores only add contention.
"""

from __future__ import annotations

from tactile_dock_ros.tools.bench import side_by_side
from tactile_dock_ros.tools.bench.docking import _at_least


def add_arguments(parser) -> None:
    side_by_side.add_arguments(parser)
    parser.add_argument(
        "--threads",
        type=_at_least(1),
        nargs="+",
        default=[1, 2],
        help="sampler thread counts, side by side (ratios are to the first)",
    )


def run(args) -> dict:
    counts = list(dict.fromkeys(args.threads))
    settings = {str(t): (lambda t=t: {"threads": t}) for t in counts}
    return {"threads": counts, **side_by_side.compare(args, settings, "thread counts")}
