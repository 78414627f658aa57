"""First look at a hold (``/evaluate_hold``): latency, and how well its P_dock ranks holds.

Held-out ground truths: ``--instances`` per problem drawn from a seed stream no other benchmark
uses (``[seed, HELD_OUT, problem, i]``; ``bench docking --split train`` draws ``[seed, problem,
i]``, the truths the planner was tuned on, and ``--split test`` the stream of
``tools.bench.splits``). Each is seen as the robot sees it, through the mock profile's depth
camera (``config/perception_mock.yaml``, a calibration error drawn per truth), and the prior
perception builds from that image is one hold: ``--prior depth`` (the default, perception's
``prior_source: depth``: the terrain classes of ``--terrain-classes`` conditioned on the image,
the generic prior out of library; ``docking.learned_prior``) or ``--prior generic`` (the
generic depth prior alone, ``perception.mock_camera.depth_prior``; the same image). For every hold
and mode (compliant, non-compliant) ``core.holds.evaluate_hold`` runs from the problem's start
with the planner's settings (the mock profile's give-up threshold), ``--samples`` prior draws
seeded with ``--eval-seed``: exactly what the perception node computes per hold.

Reported:

- latency: wall time of one evaluation (sampling and planning; the service adds its message
  conversion), ``--repeats`` times per hold and mode: p50, p99 and maximum over all of them,
  and the same over each hold's median (a load spike of the machine hits one repetition),
  per problem and pooled, against the 200 ms target;
- ranking: ROC AUC of the first look's P_dock (the whole path's, 0 on a give-up, and the best
  site's) as a score of whether the truth is feasible in the mode (``simulate.feasible``: some
  straight loading move docks on it), problems pooled and per problem, with a 95 % percentile
  bootstrap interval over the holds (``AUC_RESAMPLES``). 0.5 is chance, 1 a perfect ranking.

Deterministic per ``--seed`` and ``--eval-seed`` apart from the times.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ...core import holds, problems, simulate
from ...core.episode import PlannerConfig
from ...perception.config import PerceptionConfig, PerceptionError
from ...perception.learned_prior import TerrainLibrary
from ...perception.mock_camera import depth_prior
from ...perception.prior_select import prior_source
from .. import package_files
from .docking import (
    MODES,
    add_episode_arguments,
    add_library_arguments,
    learned_prior,
    load_library,
)

HELD_OUT = 7  # the tag of this suite's truth seeds (not drawn by any tuning benchmark)
TARGET_SECONDS = 0.2
AUC_RESAMPLES = 2000
SCORES = ("path_p_dock", "site_p_dock")


def add_arguments(parser) -> None:
    parser.add_argument("--instances", type=int, default=40, help="held-out truths per problem")
    parser.add_argument("--problems", nargs="+", default=problems.names(), choices=problems.names())
    parser.add_argument("--mode", nargs="+", default=list(MODES), choices=MODES)
    parser.add_argument("--samples", type=int, default=100, help="prior draws per evaluation")
    parser.add_argument("--eval-seed", type=int, default=0, help="seed of each evaluation")
    parser.add_argument(
        "--prior",
        type=prior_source,
        default="depth",
        choices=("depth", "generic"),
        help="depth: the image conditioned on the terrain class library (perception's default); "
        "generic: the generic depth prior of the same image (learned: the earlier name of depth)",
    )
    add_library_arguments(parser)
    add_episode_arguments(parser)


def roc_auc(scores, labels) -> float | None:
    """P(score of a positive > score of a negative), ties counted half (Mann-Whitney U / n+ n-);
    None without both classes."""
    scores, labels = np.asarray(scores, float), np.asarray(labels, bool)
    positive, negative = scores[labels], scores[~labels]
    if not len(positive) or not len(negative):
        return None
    greater = (positive[:, None] > negative[None, :]).sum()
    ties = (positive[:, None] == negative[None, :]).sum()
    return float((greater + 0.5 * ties) / (len(positive) * len(negative)))


def auc_interval(scores, labels, rng: np.random.Generator) -> list[float] | None:
    """95 % percentile-bootstrap interval of ``roc_auc``, the holds resampled with replacement
    (replicates without both classes are skipped); None without both classes."""
    scores, labels = np.asarray(scores, float), np.asarray(labels, bool)
    if roc_auc(scores, labels) is None:
        return None
    values = []
    for _ in range(AUC_RESAMPLES):
        pick = rng.integers(0, len(scores), len(scores))
        value = roc_auc(scores[pick], labels[pick])
        if value is not None:
            values.append(value)
    return [float(q) for q in np.percentile(values, [2.5, 97.5])]


def _holds(args, name: str, config: PerceptionConfig, library: TerrainLibrary | None) -> list[dict]:
    """Per held-out truth of ``name``: its prior (``library``'s, else the generic depth prior;
    None on a perception error), the model used and feasibility per mode."""
    p_index = problems.names().index(name)  # seeds do not depend on the --problems subset
    problem = problems.get(name)
    out = []
    for i in range(args.instances):
        truth = problem.sample_ground_truth(
            np.random.default_rng([args.seed, HELD_OUT, p_index, i])
        )
        entry = {
            "problem": name,
            "instance": i,
            "feasible": {
                m: bool(simulate.feasible(problem, truth, m == "compliant")) for m in MODES
            },
        }
        try:
            rng = np.random.default_rng([args.seed, HELD_OUT, p_index, i, 2])
            if library is None:
                entry["prior"], entry["model"] = depth_prior(truth, config, rng).prior, "generic"
            else:
                chosen, _ = learned_prior(
                    truth, config, rng, library, None, args.min_inlier_fraction
                )
                entry["prior"], entry["model"] = chosen.prior, chosen.model
        except PerceptionError as err:
            entry["prior"], entry["perception_error"] = None, str(err)
        out.append(entry)
    return out


def _evaluate(hold: dict, mode: str, args) -> dict:
    problem = problems.get(hold["problem"])
    config = PlannerConfig(
        problem.load,
        problem.contact_resolution,
        args.give_up_threshold,
        compliant=mode == "compliant",
    )
    seconds = []
    for _ in range(args.repeats):
        started = time.perf_counter()
        result = holds.evaluate_hold(
            hold["prior"], problem.start, config, args.samples, args.eval_seed
        )
        seconds.append(time.perf_counter() - started)
    return {
        "decision": result.decision,
        "path_p_dock": result.path_p_dock,
        "site_p_dock": result.site_p_dock,
        "reason": result.reason,
        "seconds": seconds,
    }


def _latency(seconds: list[list[float]]) -> dict:
    """Percentiles of every evaluation's time and of each hold's median (``seconds``: per hold,
    its repetitions)."""
    out = {}
    for key, values in (("", np.concatenate(seconds)), ("median_", np.median(seconds, axis=1))):
        out |= {
            f"{key}p50": float(np.percentile(values, 50)),
            f"{key}p99": float(np.percentile(values, 99)),
            f"{key}max": float(values.max()),
            f"{key}within_target": float(np.mean(values <= TARGET_SECONDS)),
        }
    return {"evaluations": sum(len(s) for s in seconds), **out}


def _ranking(rows: list[dict], rng: np.random.Generator) -> dict:
    labels = [r["feasible"] for r in rows]
    out = {"holds": len(rows), "feasible": int(sum(labels))}
    for score in SCORES:
        values = [r[score] for r in rows]
        out[f"auc_{score}"] = roc_auc(values, labels)
        out[f"auc_{score}_ci95"] = auc_interval(values, labels, rng)
    return out


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def run(args) -> dict:
    if args.instances < 1 or args.samples < 2:
        raise SystemExit("bench holds: --instances must be >= 1 and --samples >= 2")
    config = PerceptionConfig.load(package_files.resolve(args.perception_config))
    library, library_path, gates = None, None, None
    if args.prior == "depth":
        library, library_path, gates = load_library(args)
    entries = [h for name in args.problems for h in _holds(args, name, config, library)]
    records = []
    for k, hold in enumerate(entries):
        record = {key: hold[key] for key in ("problem", "instance", "feasible")}
        if hold["prior"] is None:
            record["perception_error"] = hold["perception_error"]
        else:
            record["model"] = hold["model"]
            record["vertices"] = hold["prior"].n_vertices
            record["modes"] = {mode: _evaluate(hold, mode, args) for mode in args.mode}
        records.append(record)
        print(f"[{k + 1}/{len(entries)}] {hold['problem']} #{hold['instance']}", flush=True)
    evaluated = [r for r in records if "modes" in r]
    groups = {"all": args.problems, **{name: [name] for name in args.problems}}
    rng = np.random.default_rng(args.seed)
    summary = []
    for mode in args.mode:
        for group, members in groups.items():
            rows = [
                {"feasible": r["feasible"][mode], **r["modes"][mode]}
                for r in evaluated
                if r["problem"] in members
            ]
            if not rows:
                continue
            latency = _latency([row["seconds"] for row in rows])
            summary.append(
                {"mode": mode, "problems": group, **_ranking(rows, rng), "latency": latency}
            )
    print(
        f"\n{'mode':13} {'problems':13} {'holds':>5} {'feas':>4} {'AUC path':>8} {'95% CI':>11} "
        f"{'AUC site':>8} {'p50 ms':>7} {'p99 ms':>7} {'max ms':>7} {'<=200ms':>7} "
        f"{'median p99':>10}"
    )
    for row in summary:
        ci = row["auc_path_p_dock_ci95"]
        lat = row["latency"]
        print(
            f"{row['mode']:13} {row['problems']:13} {row['holds']:>5} {row['feasible']:>4} "
            f"{_fmt(row['auc_path_p_dock'], '.3f'):>8} "
            f"{'-' if ci is None else f'{ci[0]:.2f}-{ci[1]:.2f}':>11} "
            f"{_fmt(row['auc_site_p_dock'], '.3f'):>8} {1e3 * lat['p50']:>7.1f} "
            f"{1e3 * lat['p99']:>7.1f} {1e3 * lat['max']:>7.1f} {lat['within_target']:>7.1%} "
            f"{1e3 * lat['median_p99']:>10.1f}"
        )
    return {
        "prior": args.prior,
        "terrain_classes": None if library_path is None else str(library_path.resolve()),
        "min_inlier_fraction": gates,
        "generic_fallbacks": sum(r.get("model") == "generic" for r in evaluated),
        "instances": args.instances,
        "samples": args.samples,
        "eval_seed": args.eval_seed,
        "give_up_threshold": args.give_up_threshold,
        "perception_config": str(Path(args.perception_config)),
        "target_seconds": TARGET_SECONDS,
        "perception_errors": len(records) - len(evaluated),
        "summary": summary,
        "holds": records,
    }
