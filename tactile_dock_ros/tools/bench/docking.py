"""Docking benchmark (paper Fig. 13, Sec. VI-A): ours vs growing window (GW) vs info gain (IG).

For each problem, ``--instances`` ground truths are drawn from the problem's prior (seeded, the
same truths whatever subset of problems runs) on the truths of ``--split`` (``tools.bench.splits``:
``test``, the default, is held out and is what figures quote; ``train`` are the truths the
planner was tuned on, as before the option, and anything tuned must use them; the JSON records
the split). Every truth runs one episode per strategy, per prior and per mode:

- prior ``problem``: the problem's hand-made prior; ``depth``: the prior the robot gets, what
  perception's ``prior_source: depth`` publishes for the truth rendered by the mock profile's
  depth camera (``--perception-config``, 320x240, focal 262.5 px) from a pose displaced by a
  calibration error drawn per truth from the configured extrinsic covariance (seeded): the
  terrain class library ``--terrain-classes`` (default: the shipped config/terrain_classes.npz,
  fitted on train truths by ``tools.fit_terrain_classes``) conditioned on the image, behind the
  out-of-library gate (``perception.prior_select``, ``--min-inlier-fraction``, default each
  class's), else the generic depth prior of that image; the truth records carry the model used,
  the best class, every class's log-evidence and the inlier fraction, the JSON the library path,
  the gate per class and the fallback count; ``generic`` (not run unless asked): the generic
  depth prior of the SAME image (same seeds, same draws; ``perception.mock_camera.depth_prior``),
  the out-of-library fallback alone. ``learned`` is taken as the earlier name of ``depth``;
- mode ``compliant`` (ideal compliance: the tool slides along the surface) or ``non-compliant``
  (the mock profile's planner setting, ``compliant: false`` in config/mock.yaml; with its
  executor's ``slide_on_slip``, ``--slide-on-slip``, a slip slides on for evidence only,
  ``simulate.guarded_path``; ``--no-slide-on-slip`` gives the non-compliant rows of before).

Each truth record carries, per mode, ``feasible`` (``simulate.feasible``: some straight loading
move docks) and ``holding_margin_deg`` (``simulate.holding_margin``: degrees by which its best
docking site misses holding, negative exactly when feasible; None when no loading move touches
it). Infeasible truths are split by that margin: clearly infeasible (margin >=
``CLEARLY_INFEASIBLE_DEG``, 1 degree), where the planner should give up, and near-feasible (below
1 degree: a hold a degree of friction or slope from holding, which no prior can tell from a
feasible one), whose episodes are cycles spent, not failures.

Reported per problem, prior, mode and strategy: feasible count, success on feasible truths, cycles
on feasible truths (mean, std, max), how clearly infeasible truths end (the planner's give-up, its
rate and median cycles, or the cycle cap), the near-feasible count and the mean cycles their
episodes spent, errors, ours' mean cycles over the better baseline's with its 95 % bootstrap
interval over the truths (``ratio_interval``), and the wall time of one cycle (inference + planning;
the compiled kernels are loaded before the first episode): median over all cycles, over the cycles
after each episode's first (with a history), and the maximum; and ``disagree``, the fraction of the
cycles whose sampler could check its chains (MCMC with enough draws) where they disagreed (split
R-hat over its limit or a trapped chain: ``sampling`` warns then; per cycle in each episode's
``chains_disagree``, None where nothing was checked; beside it ``mass_rounds``, the re-seed rounds
posterior mass chose, ``Convergence.mass_rounds``).

Also reported, per prior, mode and strategy (problems pooled): how well the planner's predicted
P_dock of each executed attempt matched what happened (``attempt_calibration``): the attempts,
their mean prediction, the fraction that docked, the Brier score, the expected calibration
error (10 equal bins), Spiegelhalter's z and a reliability table (``--calibration-png``: the
reliability diagrams, ``tools.bench.calibration``). A
planner that keeps predicting 15 % for attempts that dock 4 % of the time keeps exploring an
infeasible terrain: the table measures that overconfidence instead of leaving it to be guessed
from the give-up counts. With ``--workers N`` episodes run
in N processes (per-episode seeds do not depend on N); cycle times are then per process on a
machine running N episodes at once. ``--sampler-threads T`` gives each episode's sampler T
threads (the inference node's ``sampler_threads``; the same episodes in any T). Episodes are
the repetitions: ``--repeats`` is not used; ``--episode-seeds K`` runs K episodes per truth
with different sampler seeds, and the counts (``instances``, feasible, give-ups) are then over
episodes, K per truth.
"""

from __future__ import annotations

import argparse
import functools
import multiprocessing
import signal
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ...core import descent_scan, explore, hmc_exit, problems, simulate
from ...core.shape import GaussianShape
from ...perception.config import PerceptionConfig, PerceptionError
from ...perception.learned_prior import TerrainLibrary
from ...perception.mock_camera import MockCamera, depth_prior, draw_calibration_error
from ...perception.prior_select import (
    PRIOR_SOURCES,
    SelectedPrior,
    gate_thresholds,
    prior_source,
    select_prior,
)
from .. import package_files
from . import calibration
from .splits import add_split_argument, split_seed

PRIORS = ("problem", "depth")  # the default priors (``generic`` runs when asked)
TERRAIN_CLASSES = Path("config/terrain_classes.npz")
CLEARLY_INFEASIBLE_DEG = 1.0  # holding margin from which an infeasible truth is clearly so
MODES = ("compliant", "non-compliant")
PERCEPTION_CONFIG = Path(__file__).resolve().parents[3] / "config" / "perception_mock.yaml"
MOCK_PROFILE = Path(__file__).resolve().parents[3] / "config" / "mock.yaml"


def _mock_parameters(node: str) -> dict:
    """``node``'s parameters in the mock profile (``config/mock.yaml``)."""
    return yaml.safe_load(MOCK_PROFILE.read_text())[node]["ros__parameters"]


def mock_give_up_threshold() -> float:
    """The mock profile's planner ``give_up_threshold``."""
    return float(_mock_parameters("planner")["give_up_threshold"])


def mock_give_up_samples() -> int:
    """The mock profile's planner ``give_up_samples``."""
    return int(_mock_parameters("planner")["give_up_samples"])


def mock_slide_on_slip() -> bool:
    """The mock profile's executor ``slide_on_slip`` (absent: False)."""
    return bool(_mock_parameters("executor").get("slide_on_slip", False))


def _probability(text: str) -> float:
    value = float(text)
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"must be in (0, 1), got {value}")
    return value


def _at_least(minimum: int):
    def parse(text: str) -> int:
        value = int(text)
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {value}")
        return value

    return parse


def add_give_up_samples_argument(parser) -> None:
    """``--give-up-samples``: the episode loop's ``give_up_samples`` (this suite's and the
    replays' of ``bench posterior``)."""
    parser.add_argument(
        "--give-up-samples",
        type=_at_least(0),
        default=mock_give_up_samples(),
        help="a give-up after a contact is read off at least this many posterior samples: "
        "fewer are drawn on first (core.episode_posterior.draw_on; default: the mock "
        "profile's planner give_up_samples; 0: off, the paper's loop)",
    )


def add_episode_arguments(parser) -> None:
    """The episode settings this suite shares with ``bench posterior``."""
    parser.add_argument(
        "--perception-config",
        type=Path,
        default=Path("config/perception_mock.yaml"),
        help="camera extrinsic + covariance, depth noise (depth prior); a relative path missing "
        "here is taken from the installed package share (tools.package_files)",
    )
    parser.add_argument(
        "--give-up-threshold",
        type=_probability,
        default=mock_give_up_threshold(),
        help="the planner gives up below this best P_dock (default: the mock profile's; "
        "the paper's experiments: 0.001)",
    )


def add_slide_argument(parser) -> None:
    """``--slide-on-slip``, for the suites that run episodes (this one, ``bench posterior``)."""
    parser.add_argument(
        "--slide-on-slip",
        action=argparse.BooleanOptionalAction,
        default=mock_slide_on_slip(),
        help="non-compliant mode: a slip at the first contact goes on as a slide of at most "
        "simulate.MAX_SLIDE_M that is evidence along the face but never docks (default: the "
        "mock profile executor's slide_on_slip)",
    )


def add_library_arguments(parser) -> None:
    """The depth prior's class library and gate (``--prior depth``)."""
    parser.add_argument(
        "--terrain-classes",
        type=Path,
        default=TERRAIN_CLASSES,
        help="terrain class library of the depth prior (tools.fit_terrain_classes; default: "
        "the shipped one; a relative path missing here is taken from the package share)",
    )
    parser.add_argument(
        "--min-inlier-fraction",
        type=float,
        default=None,
        help="out-of-library gate of the depth prior for every class, in [0, 1] (0: never "
        "falls back; default: each class's fitted gate)",
    )


def load_library(args) -> tuple[TerrainLibrary, Path, dict[str, float]]:
    """The class library ``add_library_arguments`` named, its resolved path and the gate it
    applies per class; exits with the option's name on a bad file or gate."""
    try:
        path = package_files.resolve(args.terrain_classes)
        library = TerrainLibrary.load(path)
    except (OSError, ValueError) as err:
        raise SystemExit(f"--terrain-classes: {err}") from err
    try:
        return library, path, gate_thresholds(library, args.min_inlier_fraction)
    except ValueError as err:
        raise SystemExit(f"--min-inlier-fraction: {err}") from err


def add_arguments(parser) -> None:
    parser.add_argument("--instances", type=_at_least(1), default=20, help="truths per problem")
    parser.add_argument("--max-cycles", type=_at_least(1), default=12, help="cycle cap")
    parser.add_argument("--samples", type=_at_least(2), default=100, help="posterior samples")
    parser.add_argument("--problems", nargs="+", default=problems.names(), choices=problems.names())
    parser.add_argument(
        "--strategies", nargs="+", default=list(explore.STRATEGIES), choices=explore.STRATEGIES
    )
    parser.add_argument(
        "--prior",
        nargs="+",
        type=prior_source,
        default=list(PRIORS),
        choices=PRIOR_SOURCES,
        help="problem: the hand-made prior; depth: the mock camera's image conditioned on the "
        "terrain class library (--terrain-classes), the robot's prior; generic: the generic depth "
        "prior of the same image (learned: the earlier name of depth)",
    )
    add_library_arguments(parser)
    parser.add_argument(
        "--mode",
        nargs="+",
        default=list(MODES),
        choices=MODES,
        help="compliant: ideal compliance; non-compliant: the mock profile's",
    )
    add_episode_arguments(parser)
    add_give_up_samples_argument(parser)
    add_slide_argument(parser)
    parser.add_argument(
        "--episode-seeds",
        type=_at_least(1),
        default=1,
        help="episodes per truth, prior, mode and strategy, each with its own sampler seed (the "
        "first as with 1): averages out outcomes that change from seed to seed",
    )
    parser.add_argument("--workers", type=_at_least(1), default=1, help="episode processes")
    parser.add_argument(
        "--sampler-threads",
        type=_at_least(1),
        default=1,
        help="threads of each episode's HMC exit search (the inference node's sampler_threads): "
        "the same episodes in any count, shorter cycles where cores are free (keep workers x "
        "threads <= cores when timing)",
    )
    add_split_argument(parser)
    parser.add_argument("--quick", action="store_true", help="smoke run: 3 truths, cap 3")
    parser.add_argument(
        "--calibration-png",
        type=Path,
        default=None,
        help="write a reliability diagram of the attempts' P_dock per prior and mode into this "
        "folder (reliability_<prior>_<mode>.png, one series per strategy)",
    )


@dataclass(frozen=True)
class _Task:
    problem: str
    prior_source: str
    mode: str
    strategy: str
    instance: int
    truth: np.ndarray
    prior: GaussianShape | None  # None: no prior (perception failed)
    feasible: bool  # simulate.feasible in this mode
    holding_margin: float | None  # simulate.holding_margin in this mode, degrees (None: inf)
    seed: tuple[int, ...]
    max_cycles: int
    samples: int
    give_up_threshold: float
    slide_on_slip: bool = False
    sampler_threads: int = 1
    give_up_samples: int = 0


@functools.cache
def _problem(name: str) -> problems.Problem:
    return problems.get(name)


def episode_seed(seed: tuple[int, ...], repeat: int) -> tuple[int, ...]:
    """The sampler seed of a truth's ``repeat``-th episode (``--episode-seeds``); the first is
    the truth's own, so one episode per truth runs as before the option existed."""
    return tuple(seed) if repeat == 0 else (*seed, repeat)


def _episode(task: _Task) -> dict:
    """One episode -> JSON record (``outcome`` 'perception_error' when there is no prior)."""
    record = {"instance": task.instance, "seed": list(task.seed)}
    if task.prior is None:
        return {
            **record,
            "outcome": "perception_error",
            "docked": False,
            "cycles": 0,
            "message": "no prior",
            "p_dock": [],
            "cycle_seconds": [],
            "chains_disagree": [],
            "mass_rounds": [],
            "slide_rejected": [],
        }
    result = explore.run_episode(
        _problem(task.problem),
        task.truth,
        task.strategy,
        np.random.default_rng(task.seed),
        task.max_cycles,
        n_samples=task.samples,
        give_up_threshold=task.give_up_threshold,
        compliant=task.mode == "compliant",
        slide_on_slip=task.slide_on_slip,
        prior=task.prior,
        sampler_threads=task.sampler_threads,
        give_up_samples=task.give_up_samples,
    )
    return {
        **record,
        "outcome": result.outcome,
        "docked": result.docked,
        "cycles": result.cycles,
        "message": result.message,
        "p_dock": [c.plan.p_dock for c in result.cycles_log],
        "cycle_seconds": [c.inference_seconds + c.planning_seconds for c in result.cycles_log],
        # per cycle: the sampler's between-chain check failed (split R-hat over its limit or a
        # trapped chain); None where it could not check (independent draws, short chains)
        "chains_disagree": [_disagree(c.convergence) for c in result.cycles_log],
        # per cycle: re-seed rounds whose chains posterior mass chose (``convergence``)
        "mass_rounds": [c.convergence.mass_rounds for c in result.cycles_log],
        # per cycle: posterior draws a recorded slide ruled out (``core.episode_posterior``)
        "slide_rejected": [c.rejected for c in result.cycles_log],
    }


def _disagree(report) -> bool | None:
    if report.trapped == 0 and not np.isfinite(report.rhat):
        return None
    return not report.converged


def _holding_margin(problem: problems.Problem, truth: np.ndarray, mode: str) -> float | None:
    """``simulate.holding_margin`` in ``mode``, degrees; None (JSON) where it is inf."""
    margin = simulate.holding_margin(problem, truth, mode == "compliant")
    return float(margin) if np.isfinite(margin) else None


def learned_prior(
    truth: np.ndarray,
    config: PerceptionConfig,
    rng: np.random.Generator,
    library: TerrainLibrary,
    camera: MockCamera | None = None,
    min_inlier_fraction: float | None = None,
) -> tuple[SelectedPrior, np.ndarray]:
    """``(SelectedPrior, calibration error)``: the image ``depth_prior`` renders of ``truth``
    with the same ``rng`` (the same draws in the same order: calibration error, depth noise and,
    out of library, the occlusion samples) through ``prior_select.select_prior``. Raises
    ``PerceptionError`` like ``depth_prior``."""
    camera = MockCamera() if camera is None else camera
    error = draw_calibration_error(config.extrinsic, rng)
    depth = camera.render(truth, config, error, rng)
    chosen = select_prior(depth, camera.K, config, library, rng, min_inlier_fraction)
    return chosen, error


def _truths(
    args,
    name: str,
    instances: int,
    generic_config: PerceptionConfig | None,
    split: str = "train",
    library: TerrainLibrary | None = None,
    depth_config: PerceptionConfig | None = None,
) -> list[dict]:
    """Per instance: truth, feasibility and holding margin per mode and, when asked, its generic
    depth prior (``generic_config``) and its depth prior (``library`` with ``depth_config``: the
    same image conditioned on the class library); drawn from ``split``'s seeds
    (``splits.split_seed``; train: ``[seed, problem, i]``)."""
    p_index = problems.names().index(name)  # seeds do not depend on the --problems subset
    base = split_seed(split, args.seed)
    problem = _problem(name)
    out = []
    for i in range(instances):
        truth = problem.sample_ground_truth(np.random.default_rng([*base, p_index, i]))
        entry = {
            "instance": i,
            "truth": truth,
            "feasible": {
                mode: bool(simulate.feasible(problem, truth, mode == "compliant")) for mode in MODES
            },
            "holding_margin_deg": {mode: _holding_margin(problem, truth, mode) for mode in MODES},
            "seed": (*base, p_index, i, 1),
        }
        rng_seed = [*base, p_index, i, 2]  # the same image for both
        if generic_config is not None:
            try:
                seen = depth_prior(truth, generic_config, np.random.default_rng(rng_seed))
                entry["generic"] = seen.prior
                entry["calibration_error"] = seen.calibration_error.tolist()
            except PerceptionError as err:
                entry["generic"], entry["generic_perception_error"] = None, str(err)
        if library is not None:
            try:
                chosen, error = learned_prior(
                    truth,
                    depth_config,
                    np.random.default_rng(rng_seed),
                    library,
                    None,
                    args.min_inlier_fraction,
                )
                entry["depth"] = chosen.prior
                entry.setdefault("calibration_error", error.tolist())
                entry["learned_model"] = chosen.model
                entry["learned_class"] = chosen.learned.name
                entry["learned_log_evidence"] = chosen.learned.log_evidence
                entry["learned_inlier_fraction"] = chosen.learned.inlier_fraction
            except PerceptionError as err:
                entry["depth"], entry["perception_error"] = None, str(err)
        out.append(entry)
    return out


def _truth_record(truth: dict) -> dict:
    """The JSON part of a ``_truths`` entry: feasibility, calibration error, prior size."""
    keep = (
        "instance",
        "feasible",
        "holding_margin_deg",
        "calibration_error",
        "perception_error",
        "learned_model",
        "learned_class",
        "learned_log_evidence",
        "learned_inlier_fraction",
        "generic_perception_error",
    )
    record = {k: v for k, v in truth.items() if k in keep}
    if truth.get("generic") is not None:
        record["generic_prior_vertices"] = truth["generic"].n_vertices
    return record


def _margin(episode: dict) -> float:
    """The episode's truth's holding margin in its mode (None, or not recorded: inf)."""
    margin = episode.get("holding_margin_deg")
    return np.inf if margin is None else float(margin)


ERRORS = ("error", "perception_error")


def _summary(episodes: list[dict]) -> dict:
    """One results row. Infeasible episodes are split by their truth's holding margin: clearly
    infeasible (>= CLEARLY_INFEASIBLE_DEG) give the give-up count, rate (over all of them) and
    median cycles and the cycle cap count; near-feasible ones (below it) only the mean cycles
    they spent (episodes that ran: errors left out)."""
    feasible = [e for e in episodes if e["feasible"]]
    infeasible = [e for e in episodes if not e["feasible"]]
    clear = [e for e in infeasible if _margin(e) >= CLEARLY_INFEASIBLE_DEG]
    near = [e for e in infeasible if _margin(e) < CLEARLY_INFEASIBLE_DEG]
    near_cycles = [e["cycles"] for e in near if e["outcome"] not in ERRORS]
    cycles = np.array([e["cycles"] for e in feasible], float)
    cycle_times = [t for e in episodes for t in e["cycle_seconds"]]
    later_times = [t for e in episodes for t in e["cycle_seconds"][1:]]  # with a history
    give_up_cycles = [e["cycles"] for e in clear if e["outcome"] == "gave_up"]
    checked = [d for e in episodes for d in e["chains_disagree"] if d is not None]
    return {
        "instances": len(episodes),
        "feasible": len(feasible),
        "success_on_feasible": float(np.mean([e["docked"] for e in feasible]))
        if feasible
        else None,
        "cycles_mean": float(cycles.mean()) if len(cycles) else None,
        "cycles_std": float(cycles.std()) if len(cycles) else None,
        "cycles_max": int(cycles.max()) if len(cycles) else None,
        "feasible_gave_up": sum(e["outcome"] == "gave_up" for e in feasible),
        "clearly_infeasible": len(clear),
        "clearly_infeasible_gave_up": len(give_up_cycles),
        "clearly_infeasible_give_up_rate": len(give_up_cycles) / len(clear) if clear else None,
        "clearly_infeasible_give_up_cycles_median": float(np.median(give_up_cycles))
        if give_up_cycles
        else None,
        "clearly_infeasible_cycle_cap": sum(e["outcome"] == "cycle_cap" for e in clear),
        "near_feasible": len(near),
        "near_feasible_cycles_mean": float(np.mean(near_cycles)) if near_cycles else None,
        "errors": sum(e["outcome"] in ERRORS for e in episodes),
        "cycle_seconds_median": float(np.median(cycle_times)) if cycle_times else None,
        "later_cycle_seconds_median": float(np.median(later_times)) if later_times else None,
        "cycle_seconds_max": float(np.max(cycle_times)) if cycle_times else None,
        "chains_disagree_fraction": float(np.mean(checked)) if checked else None,
    }


CALIBRATION_BINS = (0.0, 0.1, 0.2, 0.4, 0.6, 0.8, 0.9, 1.0)
ECE_FLOOR_SEED = 0  # the outcome draws of ``calibration.calibrated_ece``


def _attempts(episode: dict) -> tuple[np.ndarray, np.ndarray]:
    """Predicted P_dock (k,) of the executed attempts and whether each docked (k,): only the
    last attempt of a docked episode did (a give-up's final plan was not executed)."""
    predicted = np.asarray(episode["p_dock"][: episode["cycles"]], float)
    docked = np.zeros(len(predicted))
    if episode["docked"] and len(docked):
        docked[-1] = 1.0
    return predicted, docked


def attempts_by_group(results: list[dict]) -> dict[tuple, tuple[np.ndarray, ...]]:
    """(prior, mode, strategy) -> (predicted P_dock, docked, truth label, attempt number from
    0 within its episode) of the executed attempts, problems pooled (the label: problem and
    instance, all episodes on one truth share it; an episode without an instance is its own
    truth); groups without an executed attempt are left out."""
    groups: dict[tuple, list[tuple[str, dict]]] = {}
    for row in results:
        key = (row["prior"], row["mode"], row["strategy"])
        for k, e in enumerate(row["episodes"]):
            truth = f"{row.get('problem')}#{e.get('instance', f'episode {k}')}"
            groups.setdefault(key, []).append((truth, e))
    out = {}
    for key, episodes in groups.items():
        pairs = [(truth, *_attempts(e)) for truth, e in episodes]  # a row has an episode
        predicted = np.concatenate([p for _, p, _ in pairs])
        if len(predicted):
            docked = np.concatenate([d for _, _, d in pairs])
            truths = np.concatenate([[t] * len(p) for t, p, _ in pairs])
            number = np.concatenate([np.arange(len(p)) for _, p, _ in pairs])
            out[key] = (predicted, docked, truths, number)
    return out


def attempt_calibration(results: list[dict]) -> list[dict]:
    """Per (prior, mode, strategy), problems pooled: attempts, mean predicted P_dock, fraction
    docked, Brier score (mean squared difference, lower is better), the expected calibration
    error (``calibration.ECE_BINS`` equal bins), Spiegelhalter's z (|z| > 1.96 rejects
    calibration), the same z grouped by truth (``calibration.clustered_spiegelhalter_z``: the
    test when ``--episode-seeds`` repeats each truth), the median and 95th percentile of the
    ECE a calibrated predictor scores on the same attempts, clustered by truth and attempt
    number (``calibration.calibrated_ece``, seeded: the same figures for the same results) and
    per bin of CALIBRATION_BINS (the last bin includes 1) the attempts, mean prediction and
    docked fraction."""
    out = []
    for (prior, mode, strategy), arrays in attempts_by_group(results).items():
        predicted, docked, truths, number = arrays
        clusters = np.char.add(truths.astype(str), np.char.add("#", number.astype(str)))
        floor = calibration.calibrated_ece(
            predicted, clusters, np.random.default_rng(ECE_FLOOR_SEED)
        )
        which = np.clip(np.digitize(predicted, CALIBRATION_BINS) - 1, 0, len(CALIBRATION_BINS) - 2)
        bins = [
            {
                "low": CALIBRATION_BINS[b],
                "high": CALIBRATION_BINS[b + 1],
                "attempts": int(np.sum(which == b)),
                "predicted": float(predicted[which == b].mean()),
                "docked": float(docked[which == b].mean()),
            }
            for b in range(len(CALIBRATION_BINS) - 1)
            if np.any(which == b)
        ]
        out.append(
            {
                "prior": prior,
                "mode": mode,
                "strategy": strategy,
                "attempts": len(predicted),
                "predicted_mean": float(predicted.mean()),
                "docked_fraction": float(docked.mean()),
                "brier": float(np.mean((predicted - docked) ** 2)),
                "ece": calibration.expected_calibration_error(predicted, docked),
                "ece_calibrated_median": float(np.median(floor)),
                "ece_calibrated_p95": float(np.percentile(floor, 95)),
                "spiegelhalter_z": calibration.spiegelhalter_z(predicted, docked),
                "spiegelhalter_z_by_truth": calibration.clustered_spiegelhalter_z(
                    predicted, docked, truths
                ),
                "truths": len(np.unique(truths)),
                "bins": bins,
            }
        )
    return out


def write_reliability_pngs(results: list[dict], folder: Path) -> list[Path]:
    """One reliability diagram per (prior, mode), a series per strategy; the paths written."""
    by_plot: dict[tuple, dict] = {}
    for (prior, mode, strategy), arrays in attempts_by_group(results).items():
        by_plot.setdefault((prior, mode), {})[strategy] = arrays[:2]
    paths = []
    for (prior, mode), series in by_plot.items():
        path = Path(folder) / f"reliability_{prior}_{mode}.png"
        calibration.reliability_png(path, f"executed attempts: {prior} prior, {mode}", series)
        paths.append(path)
    return paths


CALIBRATION_HEADER = (
    f"{'prior':7} {'mode':13} {'strategy':8} {'attempts':>8} {'predicted':>9} {'docked':>6} "
    f"{'brier':>5} {'ECE':>5} {'calibrated ECE':>14} {'z':>5} {'z/truth':>7}  bins"
)


def _floor(row: dict) -> str:
    """A calibrated predictor's ECE on the same attempts: median (95th percentile)."""
    return f"{row['ece_calibrated_median']:.3f} ({row['ece_calibrated_p95']:.3f})"


def _calibration_line(row: dict) -> str:
    bins = " ".join(
        f"[{b['low']:.1f},{b['high']:.1f}{']' if b['high'] >= 1.0 else ')'} "
        f"{b['predicted']:.2f}/{b['docked']:.2f} ({b['attempts']})"
        for b in row["bins"]
    )
    return (
        f"{row['prior']:7} {row['mode']:13} {row['strategy']:8} {row['attempts']:>8} "
        f"{row['predicted_mean']:>9.2f} {row['docked_fraction']:>6.2f} {row['brier']:>5.3f} "
        f"{row['ece']:>5.3f} {_floor(row):>14} "
        f"{row['spiegelhalter_z']:>5.2f} "
        f"{row['spiegelhalter_z_by_truth']:>7.2f}  {bins}"
    )


RATIO_RESAMPLES = 2000  # bootstrap replicates of ``ratio_interval``


def _ratios(results: list[dict]) -> None:
    """Ours' mean cycles over the better (lower) of GW and IG, per problem, prior and mode, and
    its 95 % bootstrap interval over the truths (``ratio_interval``)."""
    groups: dict[tuple, dict[str, dict]] = {}
    for row in results:
        groups.setdefault((row["problem"], row["prior"], row["mode"]), {})[row["strategy"]] = row
    for rows in groups.values():
        baselines = [rows[s]["cycles_mean"] for s in ("gw", "ig") if s in rows]
        baselines = [b for b in baselines if b is not None]
        if "ours" in rows and baselines and rows["ours"]["cycles_mean"] is not None:
            ours = rows["ours"]
            ours["ours_over_best_baseline"] = ours["cycles_mean"] / min(baselines)
            others = [rows[s]["episodes"] for s in ("gw", "ig") if s in rows]
            interval = ratio_interval(ours["episodes"], others, np.random.default_rng(0))
            ours["ours_over_best_baseline_ci95"] = interval


def _cycles_by_truth(episodes: list[dict]) -> dict[int, float]:
    """Mean cycles of each feasible truth's episodes (its ``--episode-seeds``)."""
    by_truth: dict[int, list[int]] = {}
    for e in episodes:
        if e["feasible"]:
            by_truth.setdefault(e["instance"], []).append(e["cycles"])
    return {i: float(np.mean(c)) for i, c in by_truth.items()}


def ratio_interval(
    ours: list[dict], baselines: list[list[dict]], rng: np.random.Generator
) -> list[float] | None:
    """95 % percentile-bootstrap interval of ours' mean cycles over the better baseline's, the
    feasible truths resampled with replacement (each truth with all its episodes, for every
    strategy alike: the comparison stays paired); None with fewer than 2 shared truths.

    Decision: the truths are the unit of variation (one run per truth cannot rank two methods
    whose outcomes change from seed to seed; ``--episode-seeds`` averages those within a truth),
    and the better baseline is chosen again in each replicate."""
    tables = [_cycles_by_truth(e) for e in (ours, *baselines)]
    shared = sorted(set.intersection(*(set(t) for t in tables)))
    if len(shared) < 2:
        return None
    cycles = np.array([[t[i] for i in shared] for t in tables])  # (strategies, truths)
    pick = rng.integers(0, len(shared), size=(RATIO_RESAMPLES, len(shared)))
    means = cycles[:, pick].mean(axis=2)  # (strategies, replicates)
    ratio = means[0] / means[1:].min(axis=0)
    return [float(q) for q in np.percentile(ratio, [2.5, 97.5])]


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def _interval(bounds) -> str:
    return "-" if bounds is None else f"{bounds[0]:.2f}-{bounds[1]:.2f}"


HEADER = (
    f"{'problem':13} {'prior':7} {'mode':13} {'strategy':8} {'feas':>5} {'succ':>5} "
    f"{'cyc mean':>8} {'std':>5} {'max':>4} {'clr gave up':>11} {'clr cyc':>7} {'cap':>3} "
    f"{'near':>4} {'near cyc':>8} {'err':>3} {'/best':>5} {'95% CI':>9} {'s/cycle':>7} "
    f"{'later':>6} {'max s':>6} {'disagree':>8}"
)


def _line(row: dict) -> str:
    return (
        f"{row['problem']:13} {row['prior']:7} {row['mode']:13} {row['strategy']:8} "
        f"{row['feasible']:>2}/{row['instances']:<2} "
        f"{_fmt(row['success_on_feasible'], '.0%'):>5} {_fmt(row['cycles_mean'], '.2f'):>8} "
        f"{_fmt(row['cycles_std'], '.2f'):>5} {_fmt(row['cycles_max'], 'd'):>4} "
        f"{row['clearly_infeasible_gave_up']:>5}/{row['clearly_infeasible']:<5} "
        f"{_fmt(row['clearly_infeasible_give_up_cycles_median'], '.1f'):>7} "
        f"{row['clearly_infeasible_cycle_cap']:>3} {row['near_feasible']:>4} "
        f"{_fmt(row['near_feasible_cycles_mean'], '.2f'):>8} {row['errors']:>3} "
        f"{_fmt(row.get('ours_over_best_baseline'), '.2f'):>5} "
        f"{_interval(row.get('ours_over_best_baseline_ci95')):>9} "
        f"{_fmt(row['cycle_seconds_median'], '.3f'):>7} "
        f"{_fmt(row['later_cycle_seconds_median'], '.3f'):>6} "
        f"{_fmt(row['cycle_seconds_max'], '.2f'):>6} "
        f"{_fmt(row['chains_disagree_fraction'], '.0%'):>8}"
    )


class _StopRequest:
    """SIGINT / SIGTERM handler: raises KeyboardInterrupt where the run is (a prompt stop) and
    remembers the request, so that the run also stops after the current episode if code under
    it swallowed the exception (a single-process run once finished every episode after a
    SIGTERM in CI, 2026-11-27: not reproduced, cause unknown)."""

    def __init__(self) -> None:
        self.requested = False

    def __call__(self, signum, frame) -> None:
        self.requested = True
        raise KeyboardInterrupt


def _run_all(tasks: list[_Task], workers: int) -> list[dict | None]:
    """Episodes in task order (None: not run); progress on stderr. SIGINT or SIGTERM stops the
    run and keeps the finished episodes (handlers set here: a shell starts background jobs
    with SIGINT ignored)."""
    out: list[dict | None] = [None] * len(tasks)
    stop = _StopRequest()

    def done(k: int, record: dict) -> None:
        out[k] = record
        finished = sum(r is not None for r in out)
        t = tasks[k]
        print(
            f"[{finished}/{len(tasks)}] {t.problem} {t.prior_source} {t.mode} {t.strategy} "
            f"#{t.instance} ({'feasible' if t.feasible else 'infeasible'}): "
            f"{record['outcome']} in {record['cycles']} cycles",
            file=sys.stderr,
            flush=True,
        )
        if stop.requested:
            raise KeyboardInterrupt

    handlers = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        if workers == 1:
            for k, task in enumerate(tasks):
                done(k, _episode(task))
        else:
            with multiprocessing.get_context("fork").Pool(workers, _worker_signals) as pool:
                for k, record in pool.imap_unordered(_indexed, enumerate(tasks)):
                    done(k, record)
    except KeyboardInterrupt:
        print("interrupted: reporting the finished episodes", file=sys.stderr, flush=True)
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    return out


def _worker_signals() -> None:
    """Pool workers ignore SIGINT (the parent stops the run) and die on SIGTERM. Inheriting the
    parent's handlers (SIGTERM raising KeyboardInterrupt) made ``Pool.terminate`` at the end of
    a run race with a worker waiting for its next task: measured, a worker that never exited
    and a parent waiting on it forever."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _indexed(item: tuple[int, _Task]) -> tuple[int, dict]:
    return item[0], _episode(item[1])


def run(args) -> dict:
    args.prior = list(dict.fromkeys(args.prior))  # once each (``learned`` is ``depth``)
    instances, max_cycles = (3, 3) if args.quick else (args.instances, args.max_cycles)
    config, library, library_path, gates = None, None, None, None
    if "depth" in args.prior or "generic" in args.prior:
        config = PerceptionConfig.load(package_files.resolve(args.perception_config))
    if "depth" in args.prior:
        library, library_path, gates = load_library(args)
    generic_config = config if "generic" in args.prior else None
    truths = {
        name: _truths(args, name, instances, generic_config, args.split, library, config)
        for name in args.problems
    }
    keys = [
        (name, source, mode, strategy)
        for name in args.problems
        for source in args.prior
        for mode in args.mode
        for strategy in args.strategies
    ]
    # instance-major order: a run stopped early leaves every row with its first instances
    tasks = [
        _Task(
            *key,
            i,
            truths[key[0]][i]["truth"],
            _problem(key[0]).prior if key[1] == "problem" else truths[key[0]][i][key[1]],
            truths[key[0]][i]["feasible"][key[2]],
            truths[key[0]][i]["holding_margin_deg"][key[2]],
            episode_seed(truths[key[0]][i]["seed"], repeat),
            max_cycles,
            args.samples,
            args.give_up_threshold,
            args.slide_on_slip,
            args.sampler_threads,
            args.give_up_samples,
        )
        for i in range(instances)
        for repeat in range(args.episode_seeds)
        for key in keys
    ]
    # the compiled kernels load (or compile) here, not inside the first episode's timed cycle;
    # forked workers inherit them
    hmc_exit.warm_up()
    descent_scan.warm_up()
    records = _run_all(tasks, args.workers)
    rows: dict[tuple, list[dict]] = {key: [] for key in keys}
    for task, record in zip(tasks, records, strict=True):
        if record is not None:
            key = (task.problem, task.prior_source, task.mode, task.strategy)
            margin = task.holding_margin
            rows[key].append({**record, "feasible": task.feasible, "holding_margin_deg": margin})
    results = [
        {
            "problem": name,
            "prior": source,
            "mode": mode,
            "strategy": strategy,
            **_summary(episodes),
            "episodes": episodes,
        }
        for (name, source, mode, strategy), episodes in rows.items()
        if episodes
    ]
    _ratios(results)
    print(HEADER)
    for row in results:
        print(_line(row))
    fallbacks = None
    if library is not None:
        fallbacks = {
            name: sum(t.get("learned_model") == "generic" for t in entries)
            for name, entries in truths.items()
        }
        print(f"depth prior: generic fallbacks per problem {fallbacks} (gates {gates})")
    calibration = attempt_calibration(results)
    print("\nP_dock of the executed attempts, problems pooled (bins: predicted/docked (attempts))")
    print(CALIBRATION_HEADER)
    for row in calibration:
        print(_calibration_line(row))
    if args.calibration_png is not None:
        for path in write_reliability_pngs(results, args.calibration_png):
            print(f"wrote {path}")
    return {
        "split": args.split,
        "clearly_infeasible_deg": CLEARLY_INFEASIBLE_DEG,
        "instances": instances,
        "max_cycles": max_cycles,
        "samples": args.samples,
        "give_up_threshold": args.give_up_threshold,
        "give_up_samples": args.give_up_samples,
        "slide_on_slip": args.slide_on_slip,
        "episode_seeds": args.episode_seeds,
        "workers": args.workers,
        "sampler_threads": args.sampler_threads,
        "unfinished_episodes": sum(r is None for r in records),
        "perception_config": str(args.perception_config),
        "terrain_classes": None if library_path is None else str(library_path.resolve()),
        "min_inlier_fraction": gates,
        "learned_fallbacks": fallbacks,
        "note": "wall times per process, from a shared 2-core machine "
        f"running {args.workers} episode process(es) of {args.sampler_threads} sampler "
        "thread(s)",
        "truths": {name: [_truth_record(t) for t in entries] for name, entries in truths.items()},
        "results": results,
        "attempt_calibration": calibration,
    }
