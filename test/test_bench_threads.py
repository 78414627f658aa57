"""bench threads: an episode's sampler calls again with each thread count, end to end."""

import itertools
import json

import pytest

from tactile_dock_ros.core import sampling
from tactile_dock_ros.tools import bench


def test_each_cycle_is_timed_with_every_thread_count_and_the_same_draws(tmp_path):
    """Three_ledges training truth 9 never holds under compliance (0.47 degrees from holding),
    so the quick episode (cap 3) has sampled cycles after the first: each is timed once per
    count, and the summary is taken over them."""
    out = tmp_path / "threads.json"
    assert bench.main(["threads", "--quick", "--threads", "1", "2", "3", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["threads"] == [1, 2, 3] and report["repeats"] == 1
    cycles = report["cycles"]
    assert len(cycles) >= 1 and [c["cycle"] for c in cycles] == list(range(1, len(cycles) + 1))
    assert all(b["rows"] >= a["rows"] > 0 for a, b in itertools.pairwise(cycles))
    for row in cycles:
        assert all(len(row["seconds"][t]) == 1 and row["seconds"][t][0] > 0 for t in "123")
        assert row["ratio_to_first"]["1"] == 1.0
    slowest = max(c["median_seconds"]["2"] for c in cycles)
    assert report["summary"]["slowest_cycle_seconds"]["2"] == slowest


def test_draws_that_differ_between_thread_counts_fail_the_run(tmp_path, monkeypatch):
    real = sampling.sample_posterior

    def off_by_one_thread(*args, threads=1, **kwargs):
        post = real(*args, threads=threads, **kwargs)
        if threads == 2:
            post.z[0, 0] += 1e-9
        return post

    monkeypatch.setattr(sampling, "sample_posterior", off_by_one_thread)
    with pytest.raises(SystemExit, match="draws differ between thread counts"):
        bench.main(["threads", "--quick", "--json", str(tmp_path / "t.json")])


@pytest.mark.parametrize("bad", [["--threads", "0"], ["--instance", "-1"], ["--samples", "1"]])
def test_bad_arguments_are_rejected(bad):
    with pytest.raises(SystemExit) as exit_info:
        bench.main(["threads", "--quick", *bad])
    assert exit_info.value.code == 2
