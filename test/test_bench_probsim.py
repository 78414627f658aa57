"""The probsim benchmark runs end to end on a tiny configuration and writes its JSON."""

import json

from tactile_dock_ros.tools import bench


def test_probsim_bench_small(tmp_path):
    out = tmp_path / "probsim.json"
    argv = ["probsim", "--segments", "8", "--mc", "2000", "--mc-dock", "50", "--repeats", "1"]
    argv += ["--speed-repeats", "3", "--inner", "2"]
    assert (
        bench.main([*argv, "--scipy-quadrants", "20", "--problem", "notch", "--json", str(out)])
        == 0
    )
    report = json.loads(out.read_text())
    assert set(report["app_b"]) >= {"bivariate", "univariate", "sequential"}
    speed = report["speed"]
    assert speed["sites"] == 23 and len(speed["p_dock_mc"]) == 23
    assert speed["bvn_max_abs_diff_vs_scipy"] <= 1e-10
    for key in ("speedup_vs_mc", "speedup_bivariate_vs_mc"):
        assert 0 < speed[key + "_min"] <= speed[key] <= speed[key + "_max"]
