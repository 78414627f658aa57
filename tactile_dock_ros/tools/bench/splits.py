"""Held-out protocol of the benchmarks that draw truths (``bench docking``, ``bench prior``).

``--split train``: the truths and scenes the code was tuned on, drawn from the base seed sequence
``(seed,)`` as before the option existed (so earlier JSONs reproduce with ``--split train``).
``--split test`` (the default): a disjoint stream, ``(TEST_KEY, seed)``. Figures are quoted on
test truths; anything tuned must use ``--split train``.

Why disjoint: a suite appends its own words to the base sequence (``bench docking``: problem,
instance, ...), and ``bench prior``'s train per-terrain seeds are single integers
``1000 seed + 7 i (+ 0, 1, 2)``. With ``seed`` below ``MAX_SEED`` every train entropy starts with
a 32-bit word below ``TEST_KEY``, every test entropy with ``TEST_KEY``: no train seed equals a
test seed (numpy's ``SeedSequence`` pads short entropy with trailing zeros, which cannot make
two different first words equal). ``bench holds`` draws ``[seed, 7, problem, i]``: a train-like
stream apart from both (``bench docking``'s second train word is a problem index, below 7).
"""

from __future__ import annotations

SPLITS = ("train", "test")
TEST_KEY = 0xFFFFFFFF  # the leading entropy word of the test split
MAX_SEED = 2**22  # 1000 * seed + 7 * i stays a single word below TEST_KEY


def split_seed(split: str, seed: int) -> tuple[int, ...]:
    """The base seed sequence of ``split``: ``(seed,)`` for train, ``(TEST_KEY, seed)`` for test."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if not 0 <= int(seed) < MAX_SEED:
        raise ValueError(f"seed must be in [0, {MAX_SEED}) to keep the splits apart, got {seed}")
    return (int(seed),) if split == "train" else (TEST_KEY, int(seed))


def add_split_argument(parser) -> None:
    parser.add_argument(
        "--split",
        choices=SPLITS,
        default="test",
        help="which truths: test (held out, the default; figures are quoted on these) or train "
        "(the truths the code was tuned on, as before this option; tune only on these)",
    )
