"""Probabilistic simulation: App. B accuracy of P(C_e) and the speed of P_dock per docking site.

Accuracy: random uncertain segments; each side of eq. (25) by Monte Carlo (l.h.s.: the exact
segment-segment test on samples of the edge; r.h.s.: the linearized conditions), RMSE of the
univariate (26), bivariate (30) and sequential estimates against both.
Speed: P_dock of the terminal move through every edge midpoint of a problem prior (default
three_ledges), batched, against Monte Carlo eq. (19) with N samples per site and against scipy's
bivariate CDF evaluating the same quadrants.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import multivariate_normal

from ...core import bvn, problems, probsim, simulate
from ...core.geometry2d import outward_normal


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def add_arguments(parser) -> None:
    parser.add_argument("--segments", type=int, default=1000, help="random uncertain segments")
    parser.add_argument("--mc", type=int, default=100_000, help="Monte Carlo samples per segment")
    parser.add_argument("--problem", default="three_ledges", help="prior for the speed test")
    parser.add_argument("--mc-dock", type=int, default=1000, help="eq. (19) samples per site")
    parser.add_argument("--scipy-quadrants", type=int, default=2000, help="scipy calls timed")
    parser.add_argument(
        "--speed-repeats",
        type=_positive,
        default=11,
        help="paired repetitions of the P_dock speed comparison (ratio median, min, max)",
    )
    parser.add_argument(
        "--inner", type=_positive, default=15, help="probsim calls per repetition (their mean)"
    )


def _random_segments(rng, count):
    """Uncertain edges (means (K, 4), covs (K, 4, 4)) and moves a, b (K, 2) aimed at them."""
    c = rng.uniform(-0.5, 0.5, (count, 2))
    ang = rng.uniform(0, 2 * np.pi, count)
    length = rng.uniform(0.05, 0.3, count)
    t = np.stack([np.cos(ang), np.sin(ang)], 1)
    d = c + length[:, None] * t
    root = rng.normal(size=(count, 4, 4)) * rng.uniform(0.005, 0.05, (count, 1, 1))
    covs = root @ np.swapaxes(root, 1, 2)
    normal = outward_normal(t)
    target = c + rng.uniform(-0.2, 1.2, (count, 1)) * (d - c)
    tilt = rng.uniform(-1.0, 1.0, count)
    rot = np.stack([np.cos(tilt), -np.sin(tilt), np.sin(tilt), np.cos(tilt)], 1).reshape(-1, 2, 2)
    direction = np.einsum("kij,kj->ki", rot, -normal)
    a = target - rng.uniform(0.0, 0.3, (count, 1)) * direction
    b = target + rng.uniform(0.0, 0.3, (count, 1)) * direction
    return np.hstack([c, d]), covs, a, b


def _accuracy(args, rng):
    means, covs, a, b = _random_segments(rng, args.segments)
    lhs, rhs = np.zeros(args.segments), np.zeros(args.segments)
    est = {m: np.zeros(args.segments) for m in probsim.METHODS}
    for k in range(args.segments):  # one segment per step: N x 4 samples each
        y = rng.multivariate_normal(means[k], covs[k], args.mc, method="cholesky")
        c, d = y[:, None, :2], y[:, None, 2:]
        hit = simulate.first_hits(c, d, a[k], b[k])[0]
        lhs[k] = hit.mean()
        values, grads, _ = probsim._collision_conditions(a[k], b[k], means[k : k + 1])
        lin = values[:, 0, 0][None] + (y - means[k]) @ grads[0, 0].T
        rhs[k] = np.mean(np.all(lin >= 0, axis=1))
        for m in probsim.METHODS:
            est[m][k] = probsim.segment_collision_probabilities(
                a[k], b[k], means[k : k + 1], covs[k : k + 1], m
            )[0, 0]
    rows = {}
    print(f"\nApp. B: {args.segments} random uncertain segments, Monte Carlo N = {args.mc}")
    print(f"{'method':<12}{'RMSE vs lhs':>14}{'RMSE vs rhs':>14}")
    for m in probsim.METHODS:
        r_l = float(np.sqrt(np.mean((est[m] - lhs) ** 2)))
        r_r = float(np.sqrt(np.mean((est[m] - rhs) ** 2)))
        rows[m] = {"rmse_lhs": r_l, "rmse_rhs": r_r}
        print(f"{m:<12}{r_l:>14.4f}{r_r:>14.4f}")
    rows["mc_lhs_vs_rhs_rmse"] = float(np.sqrt(np.mean((lhs - rhs) ** 2)))
    return rows


def _median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def _mean_time(fn, calls):
    """Wall seconds per call over ``calls`` back-to-back calls, and the last result."""
    t0 = time.perf_counter()
    for _ in range(calls):
        out = fn()
    return (time.perf_counter() - t0) / calls, out


def _paired_times(estimators: dict, repeats: int, calls: dict) -> tuple[dict, dict]:
    """Seconds per repetition of each estimator, timed back to back within every repetition
    (so all see the same machine load). Each is the mean over a window of ``calls[name]`` calls,
    like the Monte Carlo pass (one call over all sites): bursts of load count for both alike."""
    times = {name: [] for name in estimators}
    results = {}
    for _ in range(repeats):
        for name, fn in estimators.items():
            t, results[name] = _mean_time(fn, calls[name])
            times[name].append(t)
    return times, results


def _speed(args, rng):
    prob = problems.get(args.problem)
    shape = prob.prior
    mv = shape.mean_vertices
    mid = 0.5 * (mv[shape.edges[:, 0]] + mv[shape.edges[:, 1]])
    starts, ends = mid - 0.15 * prob.load, mid + 0.15 * prob.load
    sites = len(starts)
    res = {"problem": args.problem, "sites": sites, "vertices": shape.n_vertices}
    samples = shape.vertices(shape.sample_z(rng, args.mc_dock))

    def probsim_batch(method):
        return lambda: probsim.dock_probabilities(
            shape, starts, ends, prob.load, True, None, method
        )

    def monte_carlo():
        return [
            simulate.monte_carlo_dock_probability(samples, False, [s, e], prob.friction, prob.load)
            for s, e in zip(starts, ends, strict=True)
        ]

    estimators = {
        "sequential": probsim_batch("sequential"),
        "bivariate": probsim_batch("bivariate"),
        "mc": monte_carlo,
    }
    inner = {"sequential": args.inner, "bivariate": args.inner, "mc": 1}
    times, out = _paired_times(estimators, args.speed_repeats, inner)
    mc = out["mc"]
    res["speed_repeats"] = args.speed_repeats
    res["mc_s_per_site"] = float(np.median(times["mc"])) / sites
    res["p_dock_mc"] = mc
    for method in ("sequential", "bivariate"):
        res[f"probsim_{method}_s_per_site"] = float(np.median(times[method])) / sites
        res[f"p_dock_{method}"] = out[method][0].tolist()
        err = np.abs(out[method][0] - np.array(mc))
        res[f"mean_abs_diff_{method}_vs_mc"] = float(err.mean())
        ratios = np.array(times["mc"]) / np.array(times[method])  # per repetition
        key = "speedup_vs_mc" if method == "sequential" else "speedup_bivariate_vs_mc"
        res[key] = float(np.median(ratios))
        res[f"{key}_min"], res[f"{key}_max"] = float(ratios.min()), float(ratios.max())
    # The same quadrants through our bvn and through scipy: the collision pairs of every site.
    means, covs = shape.edge_gaussians()
    values, grads, _ = probsim._collision_conditions(starts, ends, means)
    cov_g = np.einsum("keid,edf,kejf->ijke", grads, covs, grads)
    quads = []
    for i, j in ((0, 2), (1, 3)):
        sd_i, sd_j = np.sqrt(cov_g[i, i]), np.sqrt(cov_g[j, j])
        ok = (sd_i > 0) & (sd_j > 0)
        quads.append(
            np.stack(
                [
                    values[i][ok] / sd_i[ok],
                    values[j][ok] / sd_j[ok],
                    cov_g[i, j][ok] / (sd_i * sd_j)[ok],
                ],
                1,
            )
        )
    quads = np.vstack(quads)
    quads[:, 2] = np.clip(quads[:, 2], -1, 1)
    # Quadrants beyond bvn's tail cut-off (|h| or |k| > 8.5) skip the quadrature: the ones that
    # need it are timed on their own as well.
    sets = {"": quads, "quadrature_": quads[np.all(np.abs(quads[:, :2]) <= 8.5, axis=1)]}
    res["quadrants"], res["quadrature_quadrants"] = len(quads), len(sets["quadrature_"])
    worst = 0.0
    for prefix, q in sets.items():
        if not len(q):
            continue
        t_ours, ours = _median_time(
            lambda q=q: bvn.quadrant(q[:, 0], q[:, 1], q[:, 2]), args.repeats
        )
        pick = rng.choice(len(q), min(args.scipy_quadrants, len(q)), replace=False)

        def scipy_cdf(q=q, pick=pick):
            return [
                multivariate_normal(
                    mean=[0.0, 0.0], cov=[[1.0, r], [r, 1.0]], allow_singular=True
                ).cdf([h, k])
                for h, k, r in q[pick]
            ]

        t_sp, sp = _median_time(scipy_cdf, args.repeats)
        res[f"bvn_s_per_{prefix}quadrant"] = t_ours / len(q)
        res[f"scipy_s_per_{prefix}quadrant"] = t_sp / len(pick)
        res[f"speedup_bvn_{prefix}vs_scipy"] = t_sp / len(pick) / (t_ours / len(q))
        worst = max(worst, float(np.max(np.abs(ours[pick] - np.array(sp)))))
    res["bvn_max_abs_diff_vs_scipy"] = worst
    print(
        f"\nSpeed on {args.problem}: {sites} sites, median of {args.speed_repeats} paired "
        f"repetitions (probsim: mean of {args.inner} calls each; shared machine)"
    )
    print(f"{'estimator':<34}{'ms / site':>12}{'mean |dP| vs MC':>18}")
    for method in ("sequential", "bivariate"):
        print(
            f"{'probsim ' + method:<34}{1e3 * res[f'probsim_{method}_s_per_site']:>12.3f}"
            f"{res[f'mean_abs_diff_{method}_vs_mc']:>18.4f}"
        )
    print(
        f"{'Monte Carlo eq. 19, N = ' + str(args.mc_dock):<34}{1e3 * res['mc_s_per_site']:>12.3f}"
    )
    for key, name in (("speedup_vs_mc", "sequential"), ("speedup_bivariate_vs_mc", "bivariate")):
        print(
            f"probsim {name} vs MC: {res[key]:.1f}x (min {res[key + '_min']:.1f}x, "
            f"max {res[key + '_max']:.1f}x over the repetitions)"
        )
    for prefix, name in (("", "all"), ("quadrature_", "needing quadrature")):
        if f"bvn_s_per_{prefix}quadrant" not in res:
            continue
        print(
            f"quadrants ({name}, {res[prefix + 'quadrants']}): bvn "
            f"{1e6 * res[f'bvn_s_per_{prefix}quadrant']:.3f} us, scipy "
            f"{1e6 * res[f'scipy_s_per_{prefix}quadrant']:.1f} us, "
            f"ratio {res[f'speedup_bvn_{prefix}vs_scipy']:.0f}x"
        )
    return res


def run(args) -> dict:
    rng = np.random.default_rng(args.seed)
    return {"app_b": _accuracy(args, rng), "speed": _speed(args, rng)}
