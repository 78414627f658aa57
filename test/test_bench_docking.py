"""The docking benchmark runs end to end on tiny configurations and writes its JSON."""

import json
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from tactile_dock_ros.core import problems, simulate
from tactile_dock_ros.tools import bench
from tactile_dock_ros.tools.bench import calibration, docking, splits

# a planner give-up on probability: its best P_dock and the threshold (core.planner)
GIVE_UP_BELOW = re.compile(r"best docking probability (?:of a whole path )?(\S+) < threshold (\S+)")


def test_docking_bench_small(tmp_path):
    out = tmp_path / "docking.json"
    argv = ["docking", "--instances", "3", "--max-cycles", "4", "--problems", "notch"]
    argv += ["--prior", "problem", "--mode", "compliant"]
    assert bench.main([*argv, "--strategies", "ours", "gw", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["split"] == "test" and report["clearly_infeasible_deg"] == 1.0  # the default
    notch = problems.get("notch")
    for record, entry in zip(report["truths"]["notch"], docking._truths(
        SimpleNamespace(seed=0), "notch", 3, None, "test"
    ), strict=True):  # fmt: skip
        assert set(record["holding_margin_deg"]) == set(docking.MODES)
        for mode, margin in record["holding_margin_deg"].items():
            expected = simulate.holding_margin(notch, entry["truth"], mode == "compliant")
            assert margin == pytest.approx(expected)
            assert (margin < 0) == record["feasible"][mode]
    for row in report["results"]:
        margins = [t["holding_margin_deg"]["compliant"] for t in report["truths"]["notch"]]
        assert [e["holding_margin_deg"] for e in row["episodes"]] == margins
        assert row["clearly_infeasible"] + row["near_feasible"] == 3 - row["feasible"]
    assert [r["strategy"] for r in report["results"]] == ["ours", "gw"]
    for row in report["results"]:
        assert row["instances"] == 3 and len(row["episodes"]) == 3
        times = [t for e in row["episodes"] for t in e["cycle_seconds"]]
        assert row["cycle_seconds_max"] == max(times)
        assert 0 < row["cycle_seconds_median"] <= row["cycle_seconds_max"]
        later = [t for e in row["episodes"] for t in e["cycle_seconds"][1:]]
        assert (row["later_cycle_seconds_median"] is None) == (not later)
        for e in row["episodes"]:  # one check per cycle; the first draws from the prior
            assert len(e["chains_disagree"]) == len(e["cycle_seconds"])
            assert len(e["mass_rounds"]) == len(e["cycle_seconds"])
            assert e["chains_disagree"][0] is None and e["mass_rounds"][0] == 0
    ours, gw = report["results"]
    assert ours["ours_over_best_baseline"] == pytest.approx(ours["cycles_mean"] / gw["cycles_mean"])
    low, high = ours["ours_over_best_baseline_ci95"]
    assert 0 < low <= high
    calibration = {row["strategy"]: row for row in report["attempt_calibration"]}
    for row in report["results"]:
        cal = calibration[row["strategy"]]
        assert cal["attempts"] == sum(e["cycles"] for e in row["episodes"])
        assert cal["docked_fraction"] * cal["attempts"] == pytest.approx(
            sum(e["docked"] for e in row["episodes"])
        )
        assert sum(b["attempts"] for b in cal["bins"]) == cal["attempts"]
        assert 0.0 <= cal["brier"] <= 1.0


def test_splits_draw_disjoint_truths_and_train_keeps_the_old_seeds():
    args = SimpleNamespace(seed=0)
    for p_index, name in enumerate(problems.names()):
        train, test = (docking._truths(args, name, 20, None, s) for s in ("train", "test"))
        old = [  # the seeds bench docking drew before --split
            problems.get(name).sample_ground_truth(np.random.default_rng([0, p_index, i]))
            for i in range(20)
        ]
        np.testing.assert_array_equal([t["truth"] for t in train], old)
        assert [t["seed"] for t in train] == [(0, p_index, i, 1) for i in range(20)]
        assert all(t["seed"][:2] == (splits.TEST_KEY, 0) for t in test)
        shared = [
            (i, j)
            for i, a in enumerate(train)
            for j, b in enumerate(test)
            if np.allclose(a["truth"], b["truth"])
        ]
        assert not shared
    assert splits.split_seed("train", 3) == (3,)
    assert splits.split_seed("test", 3) == (splits.TEST_KEY, 3)
    for bad in (("valid", 0), ("test", -1), ("train", splits.MAX_SEED)):
        with pytest.raises(ValueError):
            splits.split_seed(*bad)


def test_summary_splits_infeasible_truths_by_their_holding_margin():
    """Clearly infeasible (margin >= 1 degree, or no contact at all): give-ups, their rate and
    median cycles, the cycle cap; near-feasible (0 < margin < 1): mean cycles spent."""

    def episode(margin, outcome, cycles, feasible=False):
        return {
            "feasible": feasible, "holding_margin_deg": margin, "outcome": outcome,
            "cycles": cycles, "docked": outcome == "docked", "cycle_seconds": [0.1] * cycles,
            "chains_disagree": [None] * cycles,
        }  # fmt: skip

    episodes = [
        episode(-2.0, "docked", 2, feasible=True),
        episode(5.0, "gave_up", 3),
        episode(1.0, "gave_up", 6),  # exactly 1 degree: clearly infeasible
        episode(None, "gave_up", 2),  # nothing to touch: inf
        episode(12.0, "cycle_cap", 12),
        episode(0.24, "cycle_cap", 12),  # near-feasible: cycles spent, not a failure
        episode(0.62, "gave_up", 4),
        episode(0.5, "perception_error", 0),  # no episode ran: not counted in the cycles
    ]
    row = docking._summary(episodes)
    assert row["feasible"] == 1 and row["success_on_feasible"] == 1.0
    assert row["clearly_infeasible"] == 4 and row["clearly_infeasible_gave_up"] == 3
    assert row["clearly_infeasible_give_up_rate"] == pytest.approx(3 / 4)
    assert row["clearly_infeasible_give_up_cycles_median"] == 3.0
    assert row["clearly_infeasible_cycle_cap"] == 1
    assert row["near_feasible"] == 3 and row["near_feasible_cycles_mean"] == pytest.approx(8.0)
    assert row["errors"] == 1
    assert "near" in docking.HEADER and docking._line(
        {"problem": "notch", "prior": "problem", "mode": "compliant", "strategy": "ours", **row}
    ).split()[9:14] == ["3/4", "3.0", "1", "3", "8.00"]
    only_near = docking._summary(episodes[5:7])
    assert only_near["clearly_infeasible_give_up_rate"] is None
    assert only_near["clearly_infeasible_give_up_cycles_median"] is None


def _episodes(instance_cycles, feasible=True):
    return [{"instance": i, "cycles": c, "feasible": feasible} for i, c in instance_cycles]


def test_ratio_interval_resamples_truths_paired_and_averages_their_seeds():
    rng = np.random.default_rng(0)
    ours = _episodes([(0, 1), (1, 1), (2, 1)])
    gw = _episodes([(0, 2), (1, 2), (2, 2)])
    ig = _episodes([(0, 4), (1, 4), (2, 4)])
    assert docking.ratio_interval(ours, [gw, ig], rng) == pytest.approx([0.5, 0.5])
    # truth 0's two seeds average to 2 = gw's: paired, every replicate lies in [0.5, 1]
    ours = _episodes([(0, 1), (0, 3), (1, 1), (2, 1)]) + _episodes([(3, 9)], feasible=False)
    low, high = docking.ratio_interval(ours, [gw, ig], rng)
    assert 0.5 <= low < high <= 1.0
    assert docking.ratio_interval(ours[:2], [gw, ig], rng) is None  # one shared truth


def test_episode_seeds_repeat_each_truth_with_its_own_sampler_seed(tmp_path):
    out = tmp_path / "seeds.json"
    argv = ["docking", "--instances", "2", "--max-cycles", "1", "--problems", "notch"]
    argv += ["--prior", "problem", "--mode", "compliant", "--strategies", "ours"]
    assert bench.main([*argv, "--episode-seeds", "2", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    (row,) = report["results"]
    truths = docking._truths(SimpleNamespace(seed=0), "notch", 2, None, report["split"])
    truth_seeds = {t["seed"] for t in truths}
    expected = [docking.episode_seed(t, r) for t in truth_seeds for r in (0, 1)]
    assert report["episode_seeds"] == 2 and row["instances"] == 4 and len(truth_seeds) == 2
    assert sorted(tuple(e["seed"]) for e in row["episodes"]) == sorted(expected)
    assert len(set(expected)) == 4 and docking.episode_seed(next(iter(truth_seeds)), 0) in expected


def test_a_cycle_with_a_history_reports_its_chains_check(tmp_path):
    """Sloper train truths 0-2 (1 and 2 cannot be docked: holding margins 0.24 and 1.85
    degrees, so their second cycle always runs, on a history): the first cycle has no chains
    to check, every later one reports whether its HMC chains disagreed."""
    out = tmp_path / "checked.json"
    argv = ["docking", "--instances", "3", "--max-cycles", "2", "--problems", "sloper"]
    argv += ["--prior", "problem", "--mode", "compliant", "--strategies", "ours"]
    argv += ["--split", "train", "--json", str(out)]
    assert bench.main(argv) == 0
    (row,) = json.loads(out.read_text())["results"]
    infeasible = [e for e in row["episodes"] if not e["feasible"]]
    assert len(infeasible) == 2
    assert all(len(e["chains_disagree"]) == 2 for e in infeasible)
    checked = []
    for episode in row["episodes"]:
        first, *later = episode["chains_disagree"]
        assert first is None and all(x in (True, False) for x in later)
        checked += later
    assert row["chains_disagree_fraction"] == pytest.approx(np.mean(checked))


def test_chains_disagree_counts_only_the_cycles_the_sampler_checked():
    from tactile_dock_ros.core.convergence import Convergence

    assert docking._disagree(Convergence(rhat=1.5, rhat_limit=1.3)) is True
    assert docking._disagree(Convergence(rhat=1.1, rhat_limit=1.3)) is False
    assert docking._disagree(Convergence(trapped=2)) is True  # trapped, R-hat not measurable
    assert docking._disagree(Convergence()) is None  # independent draws: nothing checked
    episode = {"feasible": True, "cycles": 4, "docked": True, "outcome": "docked"}
    episode |= {"cycle_seconds": [0.1] * 4, "chains_disagree": [None, True, False, True]}
    assert docking._summary([episode])["chains_disagree_fraction"] == pytest.approx(2 / 3)
    episode["chains_disagree"] = [None] * 4
    assert docking._summary([episode])["chains_disagree_fraction"] is None


def test_attempt_calibration_scores_only_executed_attempts():
    """A docked episode's last attempt docked; a give-up's final plan was never executed; the
    bins split at CALIBRATION_BINS and P_dock 1 falls in the last."""
    episodes = [
        {"p_dock": [0.15, 0.95], "cycles": 2, "docked": True},
        {"p_dock": [0.15, 0.12, 1e-4], "cycles": 2, "docked": False},  # gave up after two
        {"p_dock": [1.0], "cycles": 1, "docked": False},  # the cycle cap
    ]
    row = {"prior": "depth", "mode": "compliant", "strategy": "ours", "episodes": episodes}
    (cal,) = docking.attempt_calibration([row])
    assert cal["attempts"] == 5 and cal["docked_fraction"] == pytest.approx(0.2)
    assert cal["predicted_mean"] == pytest.approx((0.15 + 0.95 + 0.15 + 0.12 + 1.0) / 5)
    assert cal["brier"] == pytest.approx((0.15**2 + 0.05**2 + 0.15**2 + 0.12**2 + 1.0) / 5)
    bins = {(b["low"], b["high"]): b for b in cal["bins"]}
    assert set(bins) == {(0.1, 0.2), (0.9, 1.0)}
    assert bins[(0.1, 0.2)]["attempts"] == 3 and bins[(0.1, 0.2)]["docked"] == 0.0
    assert bins[(0.9, 1.0)]["attempts"] == 2 and bins[(0.9, 1.0)]["docked"] == 0.5
    # equal bins of 0.1: [0.1, 0.2) 0.14 vs 0 docked (3), [0.9, 1] 0.975 vs 0.5 (2)
    ece = (3 * (0.15 + 0.15 + 0.12) / 3 + 2 * abs((0.95 + 1.0) / 2 - 0.5)) / 5
    assert cal["ece"] == pytest.approx(ece)
    attempts = ([0.15, 0.95, 0.15, 0.12, 1.0], [0, 1, 0, 0, 0])
    assert cal["spiegelhalter_z"] == pytest.approx(calibration.spiegelhalter_z(*attempts))
    # episodes without an instance are three truths; two on one truth are one group
    truths = [0, 0, 1, 1, 2]
    z = calibration.clustered_spiegelhalter_z(*attempts, truths)
    assert cal["spiegelhalter_z_by_truth"] == pytest.approx(z) and cal["truths"] == 3
    same = [{**e, "instance": 4} for e in episodes[:2]] + episodes[2:]
    (cal,) = docking.attempt_calibration([{**row, "episodes": same}])
    z = calibration.clustered_spiegelhalter_z(*attempts, [0, 0, 0, 0, 2])
    assert cal["spiegelhalter_z_by_truth"] == pytest.approx(z) and cal["truths"] == 2
    # the calibrated floor clusters by (truth, attempt number): the two first attempts on
    # truth 4 are one cluster, its two second attempts another, the cap's episode a third
    clusters = ["4#0", "4#1", "4#0", "4#1", "x#0"]
    floor = calibration.calibrated_ece(
        attempts[0], clusters, np.random.default_rng(docking.ECE_FLOOR_SEED)
    )
    assert cal["ece_calibrated_median"] == pytest.approx(np.median(floor))
    assert cal["ece_calibrated_p95"] == pytest.approx(np.percentile(floor, 95))
    assert 0 < cal["ece_calibrated_median"] <= cal["ece_calibrated_p95"] <= 1


def test_reliability_pngs_one_per_prior_and_mode(tmp_path):
    episodes = [{"p_dock": [0.3, 0.8], "cycles": 2, "docked": True}]
    rows = [
        {"prior": prior, "mode": "compliant", "strategy": strategy, "episodes": episodes}
        for prior in ("depth", "problem")
        for strategy in ("ours", "gw")
    ]
    paths = docking.write_reliability_pngs(rows, tmp_path)
    assert sorted(p.name for p in paths) == [
        "reliability_depth_compliant.png",
        "reliability_problem_compliant.png",
    ]
    assert all(p.stat().st_size > 0 for p in paths)


def test_the_give_up_threshold_is_the_mock_profiles_unless_given(tmp_path):
    """The planner gives up below the threshold given: at 1e-300 only where no sample docks
    (P_dock exactly 0: below any threshold), on the infeasible sloper truth (#0 of the quick
    run with seed 1) at 0.9 in its first cycle (the prior's P_dock 0.36)."""
    assert docking.mock_give_up_threshold() == 0.001  # config/mock.yaml
    argv = ["--problems", "sloper", "--prior", "problem", "--mode", "compliant"]
    default = _quick(tmp_path, "default.json", *argv)
    assert default["give_up_threshold"] == 0.001
    runs = {
        t: _quick(tmp_path, f"{t}.json", *argv, "--give-up-threshold", t) for t in ("1e-300", "0.9")
    }
    never, eager = ([e for e in runs[t]["results"][0]["episodes"]] for t in ("1e-300", "0.9"))
    assert runs["0.9"]["give_up_threshold"] == 0.9
    for episode in never:
        if episode["outcome"] == "gave_up" and "threshold" in episode["message"]:
            best, threshold = GIVE_UP_BELOW.search(episode["message"]).groups()
            assert float(best) == 0.0 and float(threshold) == 1e-300, episode["message"]
    first = eager[0]
    assert not first["feasible"] and first["outcome"] == "gave_up" and first["cycles"] == 0
    best, threshold = GIVE_UP_BELOW.search(first["message"]).groups()
    assert 0.0 < float(best) < float(threshold) == 0.9


def test_slide_on_slip_is_the_mock_profiles_unless_turned_off(tmp_path):
    """Non-compliant episodes slide on after a slip as the mock profile's executor does;
    ``--no-slide-on-slip`` runs them as before (the JSON says which)."""
    assert docking.mock_slide_on_slip()  # config/mock.yaml, executor
    argv = ["--problems", "sloper", "--prior", "problem", "--mode", "non-compliant"]
    runs = {f: _quick(tmp_path, f"{f}.json", *argv, *f.split()) for f in ("", "--no-slide-on-slip")}
    assert (
        runs[""]["slide_on_slip"] is True and runs["--no-slide-on-slip"]["slide_on_slip"] is False
    )
    assert all(r["results"][0]["errors"] == 0 for r in runs.values())


def test_the_give_up_check_is_the_mock_profiles_unless_given(tmp_path, monkeypatch):
    """``--give-up-samples`` reaches every episode (off in config/mock.yaml), the JSON says it."""
    assert docking.mock_give_up_samples() == 0
    seen, real = [], docking.explore.run_episode

    def spy(*args, **kwargs):
        seen.append(kwargs["give_up_samples"])
        return real(*args, **kwargs)

    monkeypatch.setattr(docking.explore, "run_episode", spy)
    argv = ["--problems", "sloper", "--prior", "problem", "--mode", "compliant"]
    default = _quick(tmp_path, "default.json", *argv)
    checked = _quick(tmp_path, "checked.json", *argv, "--give-up-samples", "400")
    assert (default["give_up_samples"], checked["give_up_samples"]) == (0, 400)
    assert seen == [0] * 3 + [400] * 3  # --quick: 3 truths


def _quick(tmp_path, name, *extra):
    out = tmp_path / name
    argv = ["docking", "--quick", "--strategies", "ours", "--seed", "1", "--split", "train"]
    if "--problems" not in extra:
        argv += ["--problems", "notch"]
    assert bench.main([*argv, *extra, "--json", str(out)]) == 0
    return json.loads(out.read_text())


def test_quick_generic_and_problem_priors_side_by_side(tmp_path):
    report = _quick(tmp_path, "both.json", "--prior", "generic", "problem", "--workers", "2")
    rows = {(r["prior"], r["mode"]): r for r in report["results"]}
    assert set(rows) == {
        (p, m) for p in ("generic", "problem") for m in ("compliant", "non-compliant")
    }
    assert all(r["instances"] == 3 and r["errors"] == 0 for r in rows.values())
    truths = report["truths"]["notch"]
    errors = [tuple(t["calibration_error"]) for t in truths]
    assert len(set(errors)) == 3 and all(len(e) == 6 for e in errors)  # drawn per truth
    assert all(t["generic_prior_vertices"] >= 2 for t in truths)
    # the same seeds in one process give the same episodes and the same drawn errors, also
    # with the sampler's exit search split over 2 threads
    again = _quick(
        tmp_path, "generic.json", "--prior", "generic", "--mode", "non-compliant",
        "--sampler-threads", "2",
    )  # fmt: skip
    assert report["sampler_threads"] == 1 and again["sampler_threads"] == 2
    assert [tuple(t["calibration_error"]) for t in again["truths"]["notch"]] == errors
    key = ("generic", "non-compliant")
    strip = [{k: e[k] for k in ("outcome", "cycles", "p_dock")} for e in rows[key]["episodes"]]
    assert strip == [
        {k: e[k] for k in ("outcome", "cycles", "p_dock")} for e in again["results"][0]["episodes"]
    ]


@pytest.mark.parametrize(
    "bad",
    [["--workers", "0"], ["--instances", "0"], ["--prior", "camera"], ["--mode", "stiff"],
     ["--samples", "1"], ["--max-cycles", "-2"], ["--give-up-threshold", "0"],
     ["--give-up-threshold", "1.5"], ["--seed", "-1"], ["--seed", str(2**22)],
     ["--split", "validation"], ["--sampler-threads", "0"], ["--give-up-samples", "-1"]],
)  # fmt: skip
def test_bad_arguments_are_rejected(bad):
    with pytest.raises(SystemExit) as exit_info:
        bench.main(["docking", "--quick", *bad])
    assert exit_info.value.code == 2


def test_interrupted_run_reports_the_finished_episodes(tmp_path, monkeypatch):
    from tactile_dock_ros.tools.bench import docking as bench_docking

    real, calls = bench_docking._episode, []

    def stop_after_four(task):
        calls.append(task)
        if len(calls) > 4:
            raise KeyboardInterrupt
        return real(task)

    monkeypatch.setattr(bench_docking, "_episode", stop_after_four)
    report = _quick(tmp_path, "cut.json", "--prior", "problem", "--strategies", "ours", "gw")
    assert report["unfinished_episodes"] == 3 * 2 * 2 - 4
    # instance-major order: the first truth ran in both modes with both strategies
    assert [len(r["episodes"]) for r in report["results"]] == [1, 1, 1, 1]
    assert {t.instance for t in calls[:4]} == {0}


SIGTERM_IGNORED_IN_CI = (
    "open bug (2026-11-27): in 2 of 3 fresh-clone CI runs on one machine the single-process run "
    "finished all 72 episodes after the SIGTERM (no error episodes); not reproduced outside "
    "pytest (5 manual runs, warm and cold numba cache). The handler code is shared with the "
    "2-worker case, which passes. Since 385185b a stop swallowed inside an episode now still ends "
    "the run after it (test_a_stop_swallowed_inside_an_episode_...); it passed in four CI runs "
    "before that."
)


@pytest.mark.parametrize(
    "workers",
    [pytest.param("1", marks=pytest.mark.xfail(reason=SIGTERM_IGNORED_IN_CI, strict=False)), "2"],
)
def test_sigterm_stops_a_background_run_and_writes_what_finished(tmp_path, workers):
    import os
    import signal
    import subprocess
    import sys

    out = tmp_path / "term.json"
    argv = ["docking", "--quick", "--problems", "sloper", "--prior", "depth", "--json", str(out)]
    # 72 episodes, so that a run that ignores the signal cannot pass by finishing early
    argv += ["--workers", workers, "--episode-seeds", "4"]
    process = subprocess.Popen(
        [sys.executable, "-m", "tactile_dock_ros.tools.bench", *argv],
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),  # as `cmd &` in a script
    )
    before = []
    for line in process.stderr:  # the first finished episode
        before.append(line)
        if line.startswith("[1/"):
            break
    # what the child looked like at the kill: the facts an open bug needs (see the xfail reason)
    alive = process.poll() is None
    status = Path(f"/proc/{process.pid}/status")
    masks = [s for s in status.read_text().splitlines() if s.startswith("Sig")] if alive else []
    process.send_signal(signal.SIGTERM)
    after = process.stderr.read().splitlines()
    assert process.wait(timeout=120) == 0
    report = json.loads(out.read_text())
    total = 3 * 2 * 3 * 4  # truths x modes x strategies x episode seeds
    seen = f"alive at kill: {alive}, {masks}, stderr before: {before[-3:]}, after: {after[:3]}"
    assert 0 < report["unfinished_episodes"] < total, seen
    assert (
        sum(len(r["episodes"]) for r in report["results"]) == total - report["unfinished_episodes"]
    )


def test_pool_workers_die_on_sigterm_and_leave_sigint_to_the_parent(monkeypatch):
    import signal
    from types import SimpleNamespace

    from tactile_dock_ros.tools.bench import docking as bench_docking

    def handlers(task):  # runs in the forked workers
        return {
            "outcome": "probe",
            "cycles": 0,
            "term": signal.getsignal(signal.SIGTERM) == signal.SIG_DFL,
            "int": signal.getsignal(signal.SIGINT) == signal.SIG_IGN,
        }

    monkeypatch.setattr(bench_docking, "_episode", handlers)
    task = SimpleNamespace(
        problem="sloper", prior_source="problem", mode="compliant", strategy="ours",
        instance=0, feasible=True,
    )  # fmt: skip
    records = bench_docking._run_all([task] * 4, workers=2)
    assert all(r["term"] and r["int"] for r in records)


def test_a_stop_swallowed_inside_an_episode_still_ends_a_single_process_run(monkeypatch):
    """SIGTERM during an episode whose code catches the KeyboardInterrupt (as a library might):
    the run stops after that episode and keeps it, and the handlers are restored."""
    import os
    import signal
    from types import SimpleNamespace

    from tactile_dock_ros.tools.bench import docking as bench_docking

    calls = []

    def episode(task):
        calls.append(task)
        if len(calls) == 2:
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                calls.append("not interrupted")  # the handler runs before this line
            except KeyboardInterrupt:
                pass
        return {"outcome": "probe", "cycles": 0}

    monkeypatch.setattr(bench_docking, "_episode", episode)
    task = SimpleNamespace(
        problem="sloper", prior_source="problem", mode="compliant", strategy="ours",
        instance=0, feasible=True,
    )  # fmt: skip
    before = signal.getsignal(signal.SIGTERM)
    records = bench_docking._run_all([task] * 5, workers=1)
    assert [r is not None for r in records] == [True, True, False, False, False]
    assert "not interrupted" not in calls
    assert signal.getsignal(signal.SIGTERM) == before
