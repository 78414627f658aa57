"""bench posterior: an episode's HMC posteriors beside SMC or rejection references, end to
end."""

import json

import numpy as np
import pytest

from tactile_dock_ros.core import sampling
from tactile_dock_ros.tools import bench
from tactile_dock_ros.tools.bench import posterior


def test_each_asked_cycle_is_compared_with_its_reference_give_up_included(tmp_path):
    """Sloper truth 1 on the problem prior (measured 2026-11-29: P_dock 0.349, 0.050, then a
    give-up in its third cycle, which drew on to ~400 samples when none of 100 held): the cycles
    with a history compared with an SMC reference, in sets of the loop's 100 samples."""
    out = tmp_path / "posterior.json"
    argv = ["posterior", "--problem", "sloper", "--instance", "1", "--prior", "problem"]
    argv += ["--max-cycles", "3", "--particles", "200", "--sampler-runs", "3"]
    argv += ["--json", str(out)]
    # which cycle gives up is the episode's coin (it may differ between CPUs): an episode that
    # already gave up in cycle 1 has no cycle 2, and each compared cycle is checked by the kind
    # of plan it made
    asked = [1, 2]
    try:
        code = bench.main([*argv, "--cycles", *map(str, asked)])
    except SystemExit as ended:
        assert "[2] not in this episode" in str(ended)
        asked = [1]
        code = bench.main([*argv, "--cycles", "1"])
    assert code == 0
    report = json.loads(out.read_text())
    assert report["particles"] == 200 and report["reference"] == "smc"
    assert [row["cycle"] for row in report["cycles"]] == asked
    for row in report["cycles"]:
        assert row["history_rows"] > 0 and min(row["reference_stages"]) >= 2
        if row["plan"] == "dock":
            assert 0 <= row["plan_docks_on"]["reference"] <= 1
        else:
            assert row["plan"] == "give_up" and row["plan_p_dock"] == 0.0
            assert row["plan_docks_on"] == {"hmc": None, "reference": None}  # no path to score
            assert report["outcome"] == "gave_up"
    for row in report["cycles"]:
        # the sampler's posterior is the reference's, to within the noise of 100 draws
        assert row["mean_error_max"] < 3 * row["iid_mean_error_max"]
        assert row["reference_plans"]["of"] == 4  # 2 runs x 200 draws in sets of 100
        assert 0 < row["reference_runs_mean_error_max"] < 1
        assert len(row["slide_consistent"]["reference_runs"]) == 2
        assert row["plan_p_dock"] == pytest.approx(report["p_dock"][row["cycle"]])
        # three more sampler runs of the same history: each agrees with the reference, and
        # pooled they are scored against each SMC run (the pooled mean averages the runs')
        runs = row["sampler_runs"]
        assert runs["runs"] == 3 and len(runs["pooled_to_reference_runs"]) == 2
        assert max(runs["mean_error_max_each"]) < 3 * row["iid_mean_error_max"]
        assert runs["pooled_mean_error_max"] <= max(runs["mean_error_max_each"])
        assert len(set(runs["mean_error_max_each"])) == 3  # independent runs, not one repeated


def test_a_rejection_reference_is_exact_and_a_history_it_cannot_afford_is_skipped(tmp_path):
    """--reference rejection: the cycle's samples and two more runs against prior draws that
    fit the history (exact draws: no tempering stage, the log evidence is the log acceptance
    rate); asked for more draws than the budget can accept, the cycle is skipped with the
    reason, and the run goes on."""
    out = tmp_path / "posterior.json"
    argv = ["posterior", "--problem", "sloper", "--instance", "1", "--prior", "problem"]
    argv += ["--max-cycles", "3", "--cycles", "1", "--particles", "200", "--sampler-runs", "2"]
    argv += ["--reference", "rejection", "--json", str(out)]
    assert bench.main(argv) == 0
    report = json.loads(out.read_text())
    assert report["reference"] == "rejection"
    (row,) = report["cycles"]
    assert row["reference_stages"] == [0, 0]
    assert all(-10 < e < 0 for e in row["log_evidence"])  # some prior draws fit, not all
    assert abs(row["log_evidence"][0] - row["log_evidence"][1]) < 0.5
    assert row["mean_error_max"] < 3 * row["iid_mean_error_max"]
    assert row["reference_runs_mean_error_max"] < 1
    assert max(row["sampler_runs"]["mean_error_max_each"]) < 3 * row["iid_mean_error_max"]
    assert bench.main([*argv, "--particles", "1000", "--rejection-draws", "1000"]) == 0
    (skipped,) = json.loads(out.read_text())["cycles"]
    assert skipped["cycle"] == 1 and skipped["history_rows"] == row["history_rows"]
    assert "rejection accepted" in skipped["skipped"] and "mean_error_max" not in skipped


def test_a_cycle_the_episode_did_not_reach_and_too_few_particles_are_errors():
    argv = ["posterior", "--problem", "sloper", "--prior", "problem", "--max-cycles", "1"]
    with pytest.raises(SystemExit, match=r"cycles \[5\] not in this episode"):
        bench.main([*argv, "--cycles", "5", "--particles", "100"])
    with pytest.raises(SystemExit, match="at least 2 x --samples"):
        bench.main([*argv, "--particles", "100", "--samples", "200"])
    with pytest.raises(SystemExit):  # argparse: one run has no spread to measure
        bench.main([*argv, "--references", "1"])
    with pytest.raises(SystemExit):  # argparse: no such reference, a budget below 1000 draws
        bench.main([*argv, "--reference", "mcmc"])
    with pytest.raises(SystemExit):
        bench.main([*argv, "--reference", "rejection", "--rejection-draws", "999"])
    with pytest.raises(SystemExit):  # argparse: rejection may return too few draws to score
        bench.main([*argv, "--sampler-runs", "2", "--sampler-method", "rejection"])


def test_sampler_runs_take_the_asked_method_and_start(tmp_path, monkeypatch):
    """--sampler-method gibbs --sampler-start cold: two Gibbs runs from the sampler's own
    seeding (no warm start), scored pooled against the reference."""
    calls, reports = [], []
    real = sampling.sample_posterior

    def recording(shape, history, n, rng, method="hmc", **options):
        calls.append((method, options.get("init_z") is None))
        out = real(shape, history, n, rng, method, **options)
        reports.append(out.convergence)
        return out

    monkeypatch.setattr(sampling, "sample_posterior", recording)
    out = tmp_path / "posterior.json"
    argv = ["posterior", "--problem", "sloper", "--instance", "1", "--prior", "problem"]
    argv += ["--max-cycles", "2", "--cycles", "1", "--particles", "200", "--sampler-runs", "2"]
    argv += ["--sampler-method", "gibbs", "--sampler-start", "cold", "--json", str(out)]
    assert bench.main(argv) == 0
    assert calls.count(("gibbs", True)) == 2 and all(m == "hmc" for m, _ in calls[:2])
    report = json.loads(out.read_text())
    assert report["sampler_runs"] == {"runs": 2, "method": "gibbs", "start": "cold"}
    runs = report["cycles"][0]["sampler_runs"]
    assert runs["runs"] == 2 and 0 < runs["pooled_std_ratio_median"] < 3
    assert runs["pooled_mean_error_median"] <= runs["pooled_mean_error_max"]
    # each run's own convergence report, in order (Gibbs warns often: slowly mixing chains)
    assert runs["warned_each"] == [not c.converged for c in reports[-2:]]
    assert runs["reseeded_each"] == [c.reseeded for c in reports[-2:]]
    assert runs["mass_rounds_each"] == [c.mass_rounds for c in reports[-2:]]


def test_the_depth_prior_is_checked_against_rejection(tmp_path):
    """--prior depth (the default): the robot's prior (the mock image of a training truth
    conditioned on the shipped class library). Notch truth 11 of base seed 1 is 0.27 degrees from
    holding, so its first attempt fails whatever the sampler draws and cycle 1 has a history (9
    rows measured 2026-11-29; ~7 % of prior draws fit it). The sampler's posterior is the exact
    one there: its means and the plan's P_dock agree with rejection to within the draws' noise."""
    out = tmp_path / "posterior.json"
    argv = ["posterior", "--seed", "1", "--problem", "notch", "--instance", "11"]
    argv += ["--max-cycles", "2", "--cycles", "0", "1"]
    argv += ["--reference", "rejection", "--particles", "1000", "--sampler-runs", "4"]
    assert bench.main([*argv, "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["prior"] == "depth" and report["learned_model"] == "learned"
    assert report["learned_class"] == "notch" and report["feasible"] is False
    first, second = report["cycles"]
    assert first["history_rows"] == 0 and second["history_rows"] > 0
    assert -10 < min(second["log_evidence"]) < 0  # the failure ruled some prior draws out
    for row in report["cycles"]:
        assert row["mean_error_max"] < 3 * row["iid_mean_error_max"]
        # more runs of 100 draws: none a standard deviation off (one of these 4 measured 0.40,
        # its chains' autocorrelation), pooled within test_sampling's MEAN_TOL
        runs = row["sampler_runs"]
        assert max(runs["mean_error_max_each"]) < 1.0
        assert runs["pooled_mean_error_max"] < 0.3
        # the plan docks on the sampler's 100 draws as often as on 2000 exact ones: within
        # 4 binomial standard deviations of the reference's rate
        hmc, ref = row["plan_docks_on"]["hmc"], row["plan_docks_on"]["reference"]
        assert abs(hmc - ref) <= 4 * np.sqrt(max(ref * (1 - ref), 0.01) / 100), row


def test_a_missing_class_library_is_refused_by_name():
    argv = ["posterior", "--problem", "notch", "--prior", "depth", "--max-cycles", "1"]
    with pytest.raises(SystemExit, match="--terrain-classes"):
        bench.main([*argv, "--terrain-classes", "/nonexistent/classes.npz"])


def test_split_test_replays_the_held_out_episode_bench_docking_ran(tmp_path):
    """--split test --seed S: the truth and episode of bench docking's held-out figure of that
    base seed, plan for plan (here a sloper truth on the problem prior, cap 3); the default is
    the training truth of that index, another episode; an unknown split is refused."""
    docking_out, replay_out, train_out = (tmp_path / f"{n}.json" for n in "drt")
    argv = ["--problems", "sloper", "--instances", "3", "--strategies", "ours", "--prior"]
    argv += ["problem", "--mode", "compliant", "--max-cycles", "3", "--split", "test"]
    assert bench.main(["docking", *argv, "--seed", "3", "--json", str(docking_out)]) == 0
    (result,) = json.loads(docking_out.read_text())["results"]
    episode = next(e for e in result["episodes"] if e["instance"] == 2)
    replay = ["posterior", "--problem", "sloper", "--instance", "2", "--prior", "problem"]
    replay += ["--max-cycles", "3", "--particles", "200", "--cycles", "0"]
    assert bench.main([*replay, "--split", "test", "--seed", "3", "--json", str(replay_out)]) == 0
    report = json.loads(replay_out.read_text())
    assert report["split"] == "test" and report["outcome"] == episode["outcome"]
    assert report["p_dock"] == pytest.approx(episode["p_dock"], abs=0, rel=0)
    assert bench.main([*replay, "--seed", "3", "--json", str(train_out)]) == 0
    trained = json.loads(train_out.read_text())
    assert trained["split"] == "train" and trained["p_dock"][0] != report["p_dock"][0]
    with pytest.raises(SystemExit):
        bench.main([*replay, "--split", "validation"])


def _keep_every_other_reference_draw(monkeypatch, keep_runs_to=None):
    """Slides that leave every other reference draw (or ``keep_runs_to`` draws of each run)
    and every sample of the loop; records what was scored against what."""
    real_errors = posterior._mean_errors
    scored = []

    def consistent(view, shape, samples):
        keep = np.zeros(len(samples), dtype=bool)
        if samples is view.samples:
            keep[:] = True
        elif keep_runs_to is None:
            keep[::2] = True
        else:
            keep[:keep_runs_to] = True
        return keep

    def errors(samples, ref):
        scored.append((len(samples), len(ref)))
        return real_errors(samples, ref)

    monkeypatch.setattr(posterior, "_slide_consistent", consistent)
    monkeypatch.setattr(posterior, "_mean_errors", errors)
    return scored


def test_the_loops_samples_are_scored_against_the_reference_draws_the_slides_leave(
    tmp_path, monkeypatch
):
    """The loop's samples are conditioned on the recorded slides (episode_posterior.draw): the
    noise floor, the runs' spread, the plan's docking share and the reference plans use the
    reference draws the slides leave; the repeated sampler runs, which sample the rows alone,
    are scored against every reference draw."""
    scored = _keep_every_other_reference_draw(monkeypatch)
    out = tmp_path / "posterior.json"
    argv = ["posterior", "--problem", "sloper", "--instance", "1", "--prior", "problem"]
    argv += ["--max-cycles", "2", "--cycles", "1", "--particles", "400", "--sampler-runs", "2"]
    assert bench.main([*argv, "--json", str(out)]) == 0
    (row,) = json.loads(out.read_text())["cycles"]
    m = scored[2][0]  # the loop's samples of the cycle
    n = min(m, 100)  # as many as the loop asked for: the sets of the floor and the plans
    assert row["slide_consistent"]["reference"] == 0.5
    assert row["reference_plans"]["of"] == 400 // n  # sets of n of the 400 kept draws
    # floor, runs apart, the loop's samples: the 400 kept draws (200 of each run)
    assert scored[:3] == [(n, 400 - n), (200, 200), (m, 400)]
    # the sampler runs pooled, each alone, pooled against each run: every draw
    assert scored[3:] == [(2 * n, 800), (n, 800), (n, 800), (2 * n, 400), (2 * n, 400)]


@pytest.mark.parametrize("kept", [2, 1])
def test_a_cycle_whose_slides_leave_too_few_reference_draws_is_skipped(tmp_path, monkeypatch, kept):
    """Fewer than two sets of the cycle's samples in all (2 + 2 of 2 x 200), or a run with
    no spread (one draw): the cycle is skipped with the reason, the run goes on."""
    _keep_every_other_reference_draw(monkeypatch, keep_runs_to=kept)
    out = tmp_path / "posterior.json"
    argv = ["posterior", "--problem", "sloper", "--instance", "1", "--prior", "problem"]
    argv += ["--max-cycles", "2", "--cycles", "1", "--particles", "200", "--json", str(out)]
    assert bench.main(argv) == 0
    (row,) = json.loads(out.read_text())["cycles"]
    assert f"the recorded slides leave [{kept}, {kept}] of 200 draws" in row["skipped"]
    assert "mean_error_max" not in row
