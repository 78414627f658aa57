"""bench holds: runs end to end on a tiny configuration; its ROC AUC is the Mann-Whitney one."""

import json

import numpy as np
import pytest

from tactile_dock_ros.core import problems
from tactile_dock_ros.tools import bench
from tactile_dock_ros.tools.bench import holds


def test_holds_are_the_robots_prior_unless_generic_is_asked(tmp_path):
    """--prior depth (the default) ranks the priors perception publishes: the class library on
    the image; --prior generic the generic depth prior of the same image."""
    argv = ["holds", "--instances", "2", "--repeats", "1", "--problems", "notch", "--samples", "20"]
    reports = {}
    for prior in ("depth", "generic"):
        out = tmp_path / f"{prior}.json"
        assert bench.main([*argv, "--prior", prior, "--json", str(out)]) == 0
        reports[prior] = json.loads(out.read_text())
    depth, generic = reports["depth"], reports["generic"]
    assert depth["prior"] == "depth" and generic["prior"] == "generic"
    assert generic["terrain_classes"] is None and depth["terrain_classes"].endswith(".npz")
    notch_vertices = problems.get("notch").prior.n_vertices
    for hold in depth["holds"]:
        assert (hold["model"] == "learned") == (hold["vertices"] == notch_vertices)
    assert depth["generic_fallbacks"] == sum(h["model"] == "generic" for h in depth["holds"])
    assert depth["generic_fallbacks"] < 2  # notch's own test truths: its class explains them
    assert all(h["model"] == "generic" for h in generic["holds"])
    assert generic["generic_fallbacks"] == 2
    assert [h["feasible"] for h in depth["holds"]] == [h["feasible"] for h in generic["holds"]]


def test_holds_bench_small(tmp_path):
    out = tmp_path / "holds.json"
    argv = ["holds", "--instances", "2", "--repeats", "2", "--problems", "sloper", "notch"]
    assert bench.main([*argv, "--samples", "20", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert len(report["holds"]) == 4 and report["samples"] == 20
    evaluated = [h for h in report["holds"] if "modes" in h]
    assert len(evaluated) == 4 - report["perception_errors"]
    for hold in evaluated:
        for mode, result in hold["modes"].items():
            assert len(result["seconds"]) == 2 and mode in hold["feasible"]
            assert 0.0 <= result["path_p_dock"] <= 1.0 and 0.0 <= result["site_p_dock"] <= 1.0
            assert (result["decision"] == "give_up") <= (result["path_p_dock"] == 0.0)
    rows = {(r["mode"], r["problems"]): r for r in report["summary"]}
    for mode in ("compliant", "non-compliant"):
        pooled = rows[(mode, "all")]
        assert pooled["holds"] == len(evaluated)
        assert pooled["holds"] == sum(rows[(mode, p)]["holds"] for p in ("sloper", "notch"))
        times = [t for h in evaluated for t in h["modes"][mode]["seconds"]]
        latency = pooled["latency"]
        assert latency["evaluations"] == len(times) and latency["max"] == max(times)
        assert 0 < latency["p50"] <= latency["p99"] <= latency["max"]
        medians = [np.median(h["modes"][mode]["seconds"]) for h in evaluated]
        assert latency["median_max"] == max(medians)
        assert 0 < latency["median_p50"] <= latency["median_p99"] <= latency["median_max"]


def test_roc_auc_counts_ordered_pairs_and_half_ties():
    assert holds.roc_auc([0.9, 0.8, 0.1], [True, True, False]) == 1.0
    assert holds.roc_auc([0.1, 0.8, 0.9], [True, True, False]) == 0.0
    assert holds.roc_auc([0.5, 0.5], [True, False]) == 0.5
    # positives 0.7, 0.2; negatives 0.2, 0.1: pairs > 3, one tie -> 3.5 / 4
    assert holds.roc_auc([0.7, 0.2, 0.2, 0.1], [True, True, False, False]) == pytest.approx(0.875)
    assert holds.roc_auc([0.3, 0.4], [True, True]) is None


def test_auc_interval_brackets_the_auc_and_needs_both_classes():
    scores, labels = [0.9, 0.7, 0.6, 0.4, 0.3, 0.2], [True, True, False, True, False, False]
    low, high = holds.auc_interval(scores, labels, np.random.default_rng(0))
    assert 0.0 <= low <= holds.roc_auc(scores, labels) <= high <= 1.0
    assert holds.auc_interval([0.1, 0.2], [False, False], np.random.default_rng(0)) is None
