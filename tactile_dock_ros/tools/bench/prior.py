"""Calibration of the generic depth prior: 2-sigma coverage, proper scores, independent vs
correlated.

Terrains: ``--random`` walls of ``scenes.random_terrain`` and ``--per-problem`` ground truths of
each benchmark problem (``sample_ground_truth``), all seen by the mock camera of
``config/perception_mock.yaml`` (its pose, depth noise and slice settings; 320x240 px, 262.5 px
focal length as ``mock_hardware``) displaced by a calibration error DRAWN per terrain from the
config's extrinsic covariance. The image goes through ``--encoding`` bytes (16UC1: mm steps)
and ``perceive`` builds both priors from the same image and the same occlusion seed:
``depth_model: independent`` (the original) and ``correlated`` (default). Reported per model:
pooled 2-sigma band coverage of the truth points the prior spans (``evaluation.coverage``:
in view and between the prior's ends along the truth, 1 cm apart, split into seen and hidden;
target [0.93, 0.99]); the pooled 2-sigma coverage of the seen edges' directions
(``evaluation.edge_angle_errors``: the chord between two matched truth points against the
edge's direction std; a hold is decided by a direction); the Gaussian NLL per vertex and the
energy score of the truth points matched to the seen mean vertices
(``evaluation.matched_truth``: the drawn calibration motion applied, then along the vertex
normal onto the truth; ``evaluation.deviation_score``; lower is better, also compared per
terrain); the number of basis columns, the median per-edge angle std and the median
correlation of neighbouring edges' angles. Deterministic per
``--seed`` and ``--split`` (``tools.bench.splits``: ``test``, the default, draws terrains and
camera errors from a held-out seed stream and is what figures quote; ``train`` draws them as
before the option and is what the depth model was tuned on; the JSON records the split);
``--repeats`` is unused (nothing is timed).

``--learned`` also scores what perception's ``prior_source: depth`` (the robot's prior) publishes
for the same image (``perception.prior_select`` with the ``--terrain-classes`` library and its
gates): per kind, the generic fallbacks, the class accuracy, the same 2-sigma band coverage of the
truth points, and, where the class is the truth's own problem, the vertex coverage (each truth
vertex inside its vertex's 2-D 2-sigma ellipse, 0.954 for a calibrated Gaussian: the class's
vertices correspond to the problem's truth vertices).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ...core import problems
from ...perception import evaluation, scenes
from ...perception.config import PerceptionConfig, PerceptionError
from ...perception.depth import decode_depth, encode_depth
from ...perception.learned_prior import TerrainLibrary
from ...perception.prior_select import gate_thresholds, select_prior
from ...perception.render import render_depth
from ...perception.terrain_prior import perceive
from .. import package_files
from .splits import add_split_argument, split_seed

MOCK_CONFIG = Path(__file__).resolve().parents[3] / "config" / "perception_mock.yaml"
IMAGE = (320, 240)
FOCAL_PX = 262.5
COVERAGE_SPACING_M = 0.01
TARGET_COVERAGE = (0.93, 0.99)
MODELS = ("independent", "correlated")  # old, new
CHI2_2D_2SIGMA = float(-2.0 * np.log(1.0 - 0.954))  # a 2-D Gaussian's 2-sigma (95.4 %) ellipse


def add_arguments(parser) -> None:
    parser.add_argument("--random", type=int, default=150, help="random walls")
    parser.add_argument("--per-problem", type=int, default=20, help="truths per problem")
    parser.add_argument(
        "--config",
        type=Path,
        default=Path("config/perception_mock.yaml"),
        help="perception settings; a relative path missing here is taken from the installed "
        "package share (tools.package_files)",
    )
    parser.add_argument("--encoding", default="16UC1", choices=("16UC1", "32FC1"))
    parser.add_argument(
        "--calibration-scale",
        type=float,
        default=1.0,
        help="scale of the drawn calibration error (0: a perfectly calibrated camera)",
    )
    parser.add_argument(
        "--learned",
        action="store_true",
        help="also score the terrain class library's prior (perception's prior_source: depth) "
        "of each image",
    )
    parser.add_argument(
        "--terrain-classes",
        type=Path,
        default=Path("config/terrain_classes.npz"),
        help="terrain class library of --learned (its fitted gates are used)",
    )
    add_split_argument(parser)


def mock_intrinsics(width: int = IMAGE[0], height: int = IMAGE[1], focal_px: float = FOCAL_PX):
    return np.array(
        [[focal_px, 0.0, (width - 1) / 2], [0.0, focal_px, (height - 1) / 2], [0, 0, 1]]
    )


def terrains(n_random: int, per_problem: int, seed):
    """(label, truth vertices) of the suite, deterministic per seed (an int or a sequence, as
    ``splits.split_seed`` gives)."""
    rng = np.random.default_rng(seed)
    for i in range(n_random):
        yield f"random_{i}", scenes.random_terrain(rng)
    for name in problems.names():
        problem = problems.get(name)
        for i in range(per_problem):
            yield f"{name}_{i}", problem.sample_ground_truth(rng)


def terrain_seed(split: str, seed: int, index: int):
    """The seed of the ``index``-th terrain's scoring: train ``1000 seed + 7 index`` (as before
    ``--split``), test ``(*split_seed("test", seed), 1, index)`` (the 1 keeps it apart from the
    terrains' own stream, ``split_seed``, which numpy pads with zeros)."""
    base = split_seed(split, seed)
    return 1000 * seed + 7 * index if split == "train" else (*base, 1, index)


def _offset(seed, k: int):
    """``seed + k`` for an int seed (train), ``(*seed, k)`` for a sequence (test)."""
    return seed + k if isinstance(seed, (int, np.integer)) else (*seed, k)


def _image(truth, config: PerceptionConfig, K, encoding: str, seed, calibration_scale: float):
    """(decoded depth image, drawn calibration error) of ``truth`` (``seed``'s draws)."""
    rng = np.random.default_rng(seed)
    error = calibration_scale * rng.multivariate_normal(np.zeros(6), config.extrinsic.covariance)
    depth = render_depth(
        truth, K, config.extrinsic.T_plane_camera, IMAGE, rng, config.depth_noise, error
    )
    data, step = encode_depth(depth, encoding)
    return decode_depth(data, IMAGE[1], IMAGE[0], encoding, False, step), error


def vertex_coverage(prior, truth: np.ndarray) -> int:
    """Truth vertices inside their prior vertex's 2-D 2-sigma ellipse (same vertex order)."""
    n = prior.n_vertices
    B = prior.basis.reshape(n, 2, -1)
    S = B @ B.transpose(0, 2, 1) + 1e-12 * np.eye(2)
    err = np.asarray(truth, float) - prior.mean_vertices
    return int(np.sum(np.einsum("ni,nij,nj->n", err, np.linalg.inv(S), err) <= CHI2_2D_2SIGMA))


def score_learned(depth, truth, kind: str, config, K, library: TerrainLibrary, seed) -> dict:
    """The learned prior's scores on one image (``--learned``)."""
    try:
        chosen = select_prior(depth, K, config, library, np.random.default_rng(_offset(seed, 3)))
    except PerceptionError as err:
        return {"error": str(err)}
    prior = chosen.prior
    frac, count = evaluation.coverage(prior, truth, chosen.learned.rays.origin, COVERAGE_SPACING_M)
    own = chosen.model == "learned" and kind == chosen.class_name
    return {
        "model": chosen.model,
        "class": chosen.learned.name,
        "inlier_fraction": chosen.learned.inlier_fraction,
        "covered": frac * count,
        "points": count,
        "vertices_covered": vertex_coverage(prior, truth) if own else 0,
        "vertices": prior.n_vertices if own else 0,
    }


def summarize_learned(rows: list[dict], kinds: list[str]) -> dict:
    sel = [(r["kind"], r["learned"]) for r in rows if r["kind"] in kinds and "learned" in r]
    scored = [s for _, s in sel if "error" not in s]
    learned = [(k, s) for k, s in sel if s.get("model") == "learned"]
    vertices = sum(s["vertices"] for s in scored)
    return {
        "terrains": len(sel),
        "no_prior": len(sel) - len(scored),
        "generic_fallbacks": sum(s["model"] == "generic" for s in scored),
        "class_correct": sum(k == s["class"] for k, s in learned),
        "learned": len(learned),
        "coverage_2sigma": sum(s["covered"] for s in scored)
        / max(sum(s["points"] for s in scored), 1),
        "vertex_coverage_2sigma": (
            sum(s["vertices_covered"] for s in scored) / vertices if vertices else None
        ),
    }


def score_terrain(
    truth, config: PerceptionConfig, K, encoding: str, seed, calibration_scale: float = 1.0
) -> dict:
    """Both models' scores on one terrain ({"error": ...} when the camera makes no prior);
    ``seed``: an int, or a sequence (``terrain_seed``)."""
    depth, error = _image(truth, config, K, encoding, seed, calibration_scale)
    return score_image(depth, error, truth, config, K, seed)


def score_image(depth, error, truth, config: PerceptionConfig, K, seed) -> dict:
    """``score_terrain`` on the image ``depth`` of ``truth`` seen with calibration error
    ``error``."""
    out = {"calibration_error": error.tolist()}
    for model in MODELS:
        surface = dataclasses.replace(config.surface, depth_model=model)
        # Tails past the slice ends measure nothing (a closure for the planner): scored is the
        # slice's prior.
        untailed = dataclasses.replace(config.occlusion, tail_m=0.0)
        cfg = dataclasses.replace(config, surface=surface, occlusion=untailed)
        try:
            result = perceive(depth, K, cfg, np.random.default_rng(_offset(seed, 1)))
        except PerceptionError as err:
            return {"error": str(err)}
        prior = result.prior
        frac, count = evaluation.coverage(prior, truth, result.slice.camera_xy, COVERAGE_SPACING_M)
        matched = evaluation.matched_truth(
            prior.mean_vertices,
            result.hidden,
            truth,
            config.extrinsic.T_plane_camera,
            error,
        )
        matched[result.hidden] = np.nan  # hidden vertices: the shared occlusion model
        score = evaluation.deviation_score(prior, matched, np.random.default_rng(_offset(seed, 2)))
        pts = evaluation.scored_truth_points(
            truth, result.slice.camera_xy, prior.mean_vertices, COVERAGE_SPACING_M
        )
        seen = evaluation.visible_from(truth, result.slice.camera_xy, pts)
        inside = evaluation.band_distance(prior, pts) <= 2.0
        std, corr = evaluation.edge_angle_stats(prior)
        angle_z = evaluation.edge_angle_errors(prior, matched)
        out[model] = {
            "covered": frac * count,
            "points": count,
            "covered_visible": int(np.sum(inside & seen)),
            "points_visible": int(np.sum(seen)),
            "angles_covered": int(np.sum(np.abs(angle_z) <= 2.0)),
            "angles": len(angle_z),
            **score,
            "columns": int(prior.n_basis),
            "vertices": int(prior.n_vertices),
            "median_edge_angle_std_deg": float(np.degrees(np.median(std))),
            "median_adjacent_angle_corr": float(np.median(corr)) if len(corr) else 0.0,
        }
    return out


def summarize(rows: list[dict], model: str, kinds: list[str]) -> dict:
    sel = [r[model] for r in rows if r["kind"] in kinds]
    return {
        "terrains": len(sel),
        "coverage_2sigma": sum(s["covered"] for s in sel) / max(sum(s["points"] for s in sel), 1),
        "coverage_2sigma_visible": sum(s["covered_visible"] for s in sel)
        / max(sum(s["points_visible"] for s in sel), 1),
        "coverage_2sigma_hidden": sum(s["covered"] - s["covered_visible"] for s in sel)
        / max(sum(s["points"] - s["points_visible"] for s in sel), 1),
        "angle_coverage_2sigma": sum(s["angles_covered"] for s in sel)
        / max(sum(s["angles"] for s in sel), 1),
        "mean_nll_per_vertex": float(np.mean([s["nll_per_vertex"] for s in sel])),
        "mean_energy_m": float(np.mean([s["energy_m"] for s in sel])),
        "median_columns": float(np.median([s["columns"] for s in sel])),
        "median_edge_angle_std_deg": float(
            np.median([s["median_edge_angle_std_deg"] for s in sel])
        ),
        "median_adjacent_angle_corr": float(
            np.median([s["median_adjacent_angle_corr"] for s in sel])
        ),
    }


def _number(value: float | None) -> str:
    return f"{'-':>15}" if value is None else f"{value:15.3f}"


def run(args) -> dict:
    config = PerceptionConfig.load(package_files.resolve(args.config))
    library = None
    if args.learned:
        try:
            library = TerrainLibrary.load(package_files.resolve(args.terrain_classes))
        except (OSError, ValueError) as err:
            raise SystemExit(f"--terrain-classes: {err}") from err
    learned_config = dataclasses.replace(  # the scored prior has no tails (score_terrain)
        config, occlusion=dataclasses.replace(config.occlusion, tail_m=0.0)
    )
    K = mock_intrinsics()
    rows, failed = [], []
    base = split_seed(args.split, args.seed)
    for i, (label, truth) in enumerate(terrains(args.random, args.per_problem, base)):
        seed = terrain_seed(args.split, args.seed, i)
        depth, error = _image(truth, config, K, args.encoding, seed, args.calibration_scale)
        out = score_image(depth, error, truth, config, K, seed)
        if "error" in out:
            failed.append({"terrain": label, "error": out["error"]})
            continue
        kind = label.rsplit("_", 1)[0]
        if library is not None:  # the same image
            out["learned"] = score_learned(depth, truth, kind, learned_config, K, library, seed)
        rows.append({"terrain": label, "kind": kind, **out})
    kinds = sorted({r["kind"] for r in rows})
    groups = {"all": kinds, **{k: [k] for k in kinds}}
    summary = {}
    head = f"{'terrains':<14}{'n':>4}  {'coverage':>13}  {'seen':>13}  {'hidden':>13}"
    head += f"  {'edge angles':>13}  {'NLL/vertex':>15}"
    head += f"  {'energy mm':>13}"
    print(head + f"  {'columns':>9}  {'edge angle std':>15}  {'adj corr':>11}   (old / new)")
    for group, members in groups.items():
        old, new = (summarize(rows, m, members) for m in MODELS)
        ratio = [
            r["correlated"]["energy_m"] / r["independent"]["energy_m"]
            for r in rows
            if r["kind"] in members
        ]
        better_nll = np.mean(
            [
                r["correlated"]["nll_per_vertex"] < r["independent"]["nll_per_vertex"]
                for r in rows
                if r["kind"] in members
            ]
        )
        summary[group] = {
            "independent": old,
            "correlated": new,
            "median_energy_ratio_new_over_old": float(np.median(ratio)),
            "fraction_terrains_nll_better": float(better_nll),
        }
        print(
            f"{group:<14}{old['terrains']:>4}"
            f"  {old['coverage_2sigma']:5.3f} / {new['coverage_2sigma']:.3f}"
            f"  {old['coverage_2sigma_visible']:5.3f} / {new['coverage_2sigma_visible']:.3f}"
            f"  {old['coverage_2sigma_hidden']:5.3f} / {new['coverage_2sigma_hidden']:.3f}"
            f"  {old['angle_coverage_2sigma']:5.3f} / {new['angle_coverage_2sigma']:.3f}"
            f"  {old['mean_nll_per_vertex']:6.2f} / {new['mean_nll_per_vertex']:6.2f}"
            f"  {1e3 * old['mean_energy_m']:5.2f} / {1e3 * new['mean_energy_m']:5.2f}"
            f"  {old['median_columns']:4.0f} / {new['median_columns']:<4.0f}"
            f"  {old['median_edge_angle_std_deg']:6.2f} / {new['median_edge_angle_std_deg']:<6.2f}"
            f"  {old['median_adjacent_angle_corr']:5.2f} / {new['median_adjacent_angle_corr']:.2f}"
        )
    if library is not None:
        gates = ", ".join(
            f"{name} {gate:.3f}" for name, gate in gate_thresholds(library, None).items()
        )
        print(f"\nlearned prior ({args.terrain_classes}, gates {gates})")
        print(
            f"{'terrains':<14}{'n':>4}  {'fallbacks':>9}  {'class ok':>9}  {'coverage':>8}  "
            f"{'vertex coverage':>15}"
        )
        for group, members in groups.items():
            learned = summarize_learned(rows, members)
            summary[group]["learned"] = learned
            print(
                f"{group:<14}{learned['terrains']:>4}  {learned['generic_fallbacks']:>9}"
                f"  {learned['class_correct']:>4}/{learned['learned']:<4}"
                f"  {learned['coverage_2sigma']:8.3f}  {_number(learned['vertex_coverage_2sigma'])}"
            )
    print(f"target coverage {TARGET_COVERAGE}; {len(failed)} terrains gave no prior")
    return {
        "split": args.split,
        "config": str(args.config),
        "image": list(IMAGE),
        "focal_px": FOCAL_PX,
        "encoding": args.encoding,
        "calibration_scale": args.calibration_scale,
        "target_coverage": list(TARGET_COVERAGE),
        "terrain_classes": str(args.terrain_classes) if args.learned else None,
        "summary": summary,
        "failed": failed,
        "rows": rows,
    }
