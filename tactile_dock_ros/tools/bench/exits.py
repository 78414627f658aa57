"""The HMC exit search with and without its pair certificates, side by side: every cycle of
one docking episode sampled again with ``sampling.EXIT_CERTIFICATES`` on (the default) and
off (every window builds every constraint pair, ``hmc_exit``), ``--repeats`` times; per cycle
the median seconds of each and the ratio off / on. The certificates only skip pairs that
cannot turn live, so the draws must be the same: a cycle whose draws differ fails the run
(``side_by_side``: the episode, the calls, the rotating order).

Example: ``python -m tactile_dock_ros.tools.bench exits --problem three_ledges --instance 9
--episode-seed 1 --repeats 5 --json out.json``.
"""

from __future__ import annotations

from tactile_dock_ros.core import sampling
from tactile_dock_ros.tools.bench import side_by_side

add_arguments = side_by_side.add_arguments


def _certificates(on: bool):
    def apply() -> dict:
        sampling.EXIT_CERTIFICATES = on
        return {}

    return apply


def run(args) -> dict:
    settings = {"certificates": _certificates(True), "none": _certificates(False)}
    try:
        return side_by_side.compare(args, settings, "exit-search settings")
    finally:
        sampling.EXIT_CERTIFICATES = True
