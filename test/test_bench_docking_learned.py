"""``bench docking --prior depth``: the mock camera's image conditioned on the terrain class
library (``perception.learned_prior``), the generic depth prior (``--prior generic``) out of
library."""

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from tactile_dock_ros.core import problems
from tactile_dock_ros.perception.config import PerceptionConfig
from tactile_dock_ros.perception.learned_prior import TerrainLibrary
from tactile_dock_ros.perception.mock_camera import depth_prior
from tactile_dock_ros.tools import bench
from tactile_dock_ros.tools.bench import docking

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "config" / "terrain_classes.npz"
CONFIG = REPO / "config" / "perception_mock.yaml"


def test_the_learned_prior_sees_the_generic_priors_image():
    """Same seed: the same calibration error is drawn (then the same depth noise)."""
    config = PerceptionConfig.load(CONFIG)
    truth = problems.get("notch").sample_ground_truth(np.random.default_rng(1))
    seen = depth_prior(truth, config, np.random.default_rng(7))
    _, error = docking.learned_prior(
        truth, config, np.random.default_rng(7), TerrainLibrary.load(SHIPPED)
    )
    assert np.array_equal(error, seen.calibration_error)


def test_out_of_library_the_depth_row_gets_the_generic_rows_prior():
    """A library without the truth's class: the gate falls back to exactly the generic prior."""
    config = PerceptionConfig.load(CONFIG)
    truth = problems.get("notch").sample_ground_truth(np.random.default_rng(1))
    seen = depth_prior(truth, config, np.random.default_rng(7))
    shipped = TerrainLibrary.load(SHIPPED)
    others = shipped.without("notch")
    chosen, _ = docking.learned_prior(truth, config, np.random.default_rng(7), others)
    assert chosen.model == "generic"
    assert np.array_equal(chosen.prior.mean, seen.prior.mean)
    assert np.array_equal(chosen.prior.basis, seen.prior.basis)
    chosen, _ = docking.learned_prior(truth, config, np.random.default_rng(7), shipped)
    assert chosen.model == "learned" and chosen.class_name == "notch"


def test_the_default_priors_are_the_hand_made_and_the_robots():
    """``depth`` is the class library's prior; ``learned``, its earlier name, still selects it;
    the generic prior runs only when asked."""
    parser = argparse.ArgumentParser()
    docking.add_arguments(parser)
    assert parser.parse_args([]).prior == ["problem", "depth"]
    assert parser.parse_args(["--prior", "learned", "generic"]).prior == ["depth", "generic"]
    with pytest.raises(SystemExit):
        parser.parse_args(["--prior", "camera"])


def test_bench_docking_quick_with_the_depth_prior(tmp_path):
    out = tmp_path / "depth.json"
    argv = ["docking", "--quick", "--prior", "depth", "learned", "--strategies", "ours"]
    assert bench.main([*argv, "--problems", "sloper", "notch", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert Path(report["terrain_classes"]).resolve() == SHIPPED.resolve()
    assert report["min_inlier_fraction"] == TerrainLibrary.load(SHIPPED).gates
    models = {n: [t["learned_model"] for t in ts] for n, ts in report["truths"].items()}
    assert report["learned_fallbacks"] == {n: m.count("generic") for n, m in models.items()}
    assert [r["prior"] for r in report["results"]] == ["depth"] * 4  # 2 problems x 2 modes, once
    assert all(r["errors"] == 0 for r in report["results"])
    calibration = {(r["prior"], r["mode"]) for r in report["attempt_calibration"]}
    assert calibration == {("depth", m) for m in docking.MODES}
    for name, truths in report["truths"].items():
        assert [t["learned_class"] for t in truths] == [name] * 3
        assert all(len(t["calibration_error"]) == 6 for t in truths)


def test_bench_docking_refuses_a_bad_library(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"garbage")
    with pytest.raises(SystemExit, match=r"--terrain-classes: .*not a terrain class library"):
        bench.main(["docking", "--quick", "--prior", "depth", "--terrain-classes", str(bad)])
    with pytest.raises(SystemExit, match=r"--min-inlier-fraction: .*\[0, 1\]"):
        bench.main(["docking", "--quick", "--prior", "depth", "--min-inlier-fraction", "1.5"])


def test_bench_docking_loads_the_compiled_kernels_before_any_timed_cycle(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(docking.hmc_exit, "warm_up", lambda: calls.append("hmc_exit"))
    monkeypatch.setattr(docking.descent_scan, "warm_up", lambda: calls.append("descent_scan"))
    episode = docking._episode
    monkeypatch.setattr(docking, "_episode", lambda task: calls.append("episode") or episode(task))
    argv = ["docking", "--quick", "--prior", "problem", "--strategies", "ours", "--workers", "1"]
    assert bench.main([*argv, "--problems", "sloper", "--json", str(tmp_path / "x.json")]) == 0
    assert calls[:2] == ["hmc_exit", "descent_scan"] and set(calls[2:]) == {"episode"}
