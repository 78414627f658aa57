"""bench exits: an episode's sampler calls with and without the pair certificates, end to end."""

import json

import pytest

from tactile_dock_ros.core import sampling
from tactile_dock_ros.tools import bench


def test_each_cycle_is_timed_with_and_without_certificates_and_the_same_draws(tmp_path):
    """The quick episode (three_ledges training truth 9, cap 3) has sampled cycles after the
    first: each is timed once per setting, with the same draws, and the certificates are on
    again after the run."""
    out = tmp_path / "exits.json"
    assert bench.main(["exits", "--quick", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["repeats"] == 1 and sampling.EXIT_CERTIFICATES
    assert len(report["cycles"]) >= 1
    for row in report["cycles"]:
        assert set(row["median_seconds"]) == {"certificates", "none"}
        assert all(s[0] > 0 for s in row["seconds"].values())
        assert row["ratio_to_first"]["certificates"] == 1.0
    total = sum(c["median_seconds"]["none"] for c in report["cycles"])
    assert report["summary"]["total_seconds"]["none"] == pytest.approx(total)


def test_draws_that_differ_without_certificates_fail_the_run(tmp_path, monkeypatch):
    real = sampling.sample_posterior

    def drifting(*args, **kwargs):
        post = real(*args, **kwargs)
        if not sampling.EXIT_CERTIFICATES:
            post.z[0, 0] += 1e-9
        return post

    monkeypatch.setattr(sampling, "sample_posterior", drifting)
    with pytest.raises(SystemExit, match="draws differ between exit-search settings"):
        bench.main(["exits", "--quick", "--json", str(tmp_path / "e.json")])
    assert sampling.EXIT_CERTIFICATES


@pytest.mark.parametrize("bad", [["--instance", "-1"], ["--samples", "1"], ["--threads", "2"]])
def test_bad_arguments_are_rejected(bad):
    with pytest.raises(SystemExit) as exit_info:
        bench.main(["exits", "--quick", *bad])
    assert exit_info.value.code == 2
