"""Posterior sampling benchmark (paper Fig. 9): EST = seconds / ESS of rejection, MH, Gibbs and
HMC on three Sloper problems of increasing restriction and on three_ledges after 10 probes, plus
the HMC throughput (effective samples per second, one thread) on that posterior over several
runs, our HMC against the PyPI package tmg-hmc on a Brownian bridge constrained to y <= 0, and
the seeding check: HMC and Gibbs means on Fig. 9 problem 2 over many seeds against rejection.

Every number is a median over --repeats runs with different seeds (the throughput: over
--throughput-repeats runs; chains per method: CHAINS).
Wall times include pruning, seeding and verification. ESS is the autocorrelation-based
effective sample size, minimum over vertex coordinates (independent draws for rejection).
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from tactile_dock_ros.core.constraint_systems import LinearConstraints
from tactile_dock_ros.core.constraints import history_consistent
from tactile_dock_ros.core.ess import effective_sample_size
from tactile_dock_ros.core.sampling import METHODS, ChainRunner, sample_posterior
from tactile_dock_ros.core.sampling_problems import fig9_problem, three_ledges_after_probes

# HMC decorrelates within a move, so many chains may share seeds (None: the default, 16 to 256
# by sample count); the slowly mixing MH and Gibbs chains each get their own seed (<=
# SEED_DESCENTS chains), or their ESS would be inflated.
CHAINS = {"hmc": None, "gibbs": 4, "mh": 4, "rejection": 1}


def add_arguments(parser) -> None:
    parser.add_argument(
        "--samples",
        type=int,
        default=4096,
        help="samples per Sloper run (enough for stable ESS estimates of MH and Gibbs too)",
    )
    parser.add_argument(
        "--ledges-samples", type=int, default=200, help="samples per three_ledges run"
    )
    parser.add_argument(
        "--max-draws", type=int, default=4_000_000, help="rejection-sampling draw budget"
    )
    parser.add_argument(
        "--ledges-max-draws", type=int, default=100_000, help="rejection budget, three_ledges"
    )
    parser.add_argument(
        "--fraction-draws", type=int, default=400_000, help="prior draws to measure P(H)"
    )
    parser.add_argument(
        "--throughput-samples",
        type=int,
        default=1000,
        help="HMC samples per run of the three_ledges throughput measurement",
    )
    parser.add_argument(
        "--throughput-repeats",
        type=int,
        default=7,
        help="runs (distinct seeds) of the three_ledges HMC throughput measurement",
    )
    parser.add_argument("--bridge-points", type=int, default=50, help="bridge interior points")
    parser.add_argument("--bridge-samples", type=int, default=1000, help="bridge samples")
    parser.add_argument(
        "--skip-tmg", action="store_true", help="skip the tmg-hmc comparison (not installed)"
    )
    parser.add_argument(
        "--check-seeds",
        type=int,
        default=40,
        help="seeds of the Fig. 9 problem 2 posterior check against rejection (0: skip)",
    )
    parser.add_argument(
        "--check-samples", type=int, default=2000, help="samples per run of the posterior check"
    )


def _median(values):
    finite = [v for v in values if np.isfinite(v)]
    return statistics.median(finite) if finite else float("inf")


def _prior_fraction(problem, history, draws, rng) -> float:
    shape = problem.prior
    hits = 0
    for start in range(0, draws, 50_000):  # bounded memory
        z = shape.sample_z(rng, min(50_000, draws - start))
        hits += int(history_consistent(False, shape.vertices(z), history, shape.friction).sum())
    return hits / draws


def _run_problem(name, problem, history, n_samples, args, methods, max_draws) -> dict:
    fraction = _prior_fraction(problem, history, args.fraction_draws, np.random.default_rng(0))
    print(f"\n{name}: {len(history)} segments, prior feasible fraction {100 * fraction:.3f} %")
    print(f"{'method':>10} {'samples':>8} {'seconds':>9} {'ESS':>8} {'EST ms':>9} {'ESS/s':>8}")
    rows = {}
    for method in methods:
        runs = []
        for rep in range(args.repeats):
            rng = np.random.default_rng(args.seed + 1000 * rep + 17)
            out = sample_posterior(
                problem.prior,
                history,
                n_samples,
                rng,
                method,
                max_draws=max_draws,
                chains=CHAINS[method],
            )
            assert history_consistent(False, out.vertices, history, problem.friction).all()
            runs.append(
                {
                    "samples": len(out.z),
                    "seconds": out.seconds,
                    "ess": out.ess if len(out.z) else 0.0,
                    "est": out.est if len(out.z) else float("inf"),
                    "info": {k: v for k, v in out.info.items() if np.isscalar(v)},
                }
            )
        med = {key: _median([r[key] for r in runs]) for key in ("samples", "seconds", "ess", "est")}
        rate = med["ess"] / med["seconds"] if med["seconds"] > 0 else 0.0
        rows[method] = {"median": {**med, "ess_per_second": rate}, "runs": runs}
        print(
            f"{method:>10} {med['samples']:>8.0f} {med['seconds']:>9.3f} {med['ess']:>8.1f} "
            f"{1e3 * med['est']:>9.2f} {rate:>8.1f}"
        )
    return {"segments": len(history), "prior_fraction": fraction, "methods": rows}


def brownian_bridge(n: int, sigma: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Covariance square root S (n, n) of a Brownian bridge at n interior points of [0, 1] and
    those points; the occlusion prior of Sec. III-A1 before the y <= 0 constraint."""
    s = np.arange(1, n + 1) / (n + 1)
    cov = sigma**2 * (np.minimum.outer(s, s) - np.outer(s, s))
    eigval, eigvec = np.linalg.eigh(cov)
    return (eigvec * np.sqrt(eigval)) @ eigvec.T, s  # symmetric root (tmg-hmc requires it)


def _bridge(args) -> dict:
    """Our HMC (1 and 8 chains) and tmg-hmc on the bridge under y <= 0: ESS per second."""
    root, s = brownian_bridge(args.bridge_points)
    system = LinearConstraints(root, np.zeros(len(s)))  # y = S z <= 0
    n, burn = args.bridge_samples, 20
    start = -np.sqrt(s * (1 - s))  # one standard deviation below the line: feasible
    z0 = np.linalg.solve(root, start)
    print(f"\nBrownian bridge, {len(s)} points, y <= 0: {n} samples, burn-in {burn}")
    print(f"{'sampler':>16} {'seconds':>9} {'ESS':>8} {'ESS/s':>9}")
    results = {}
    samplers = {"ours_1_chain": 1, "ours_8_chains": 8}
    for name, chains in samplers.items():
        runs = []
        for rep in range(args.repeats):
            rng = np.random.default_rng(args.seed + rep)
            t0 = time.perf_counter()
            runner = ChainRunner(system, "hmc", rng)
            y = runner.run(np.tile(z0, (chains, 1)), -(-n // chains), burn_in=burn) @ root.T
            seconds = time.perf_counter() - t0
            assert np.all(y <= 1e-9)
            ess = float(effective_sample_size(y).min())
            runs.append({"seconds": seconds, "ess": ess, "ess_per_second": ess / seconds})
        results[name] = runs
    if not args.skip_tmg:
        from tmg_hmc import TMGSampler

        runs = []
        for rep in range(args.repeats):
            rng = np.random.default_rng(args.seed + rep)
            t0 = time.perf_counter()
            sampler = TMGSampler(np.zeros(len(s)), Sigma_half=root)
            for i in range(len(s)):
                sampler.add_constraint(f=-np.eye(len(s))[:, i : i + 1], c=0.0)
            # seeded momenta instead of the package's global np.random state
            sampler.sample_xdot = lambda rng=rng: rng.standard_normal((len(s), 1))
            y = sampler.sample(start, n_samples=n, burn_in=burn)
            seconds = time.perf_counter() - t0
            assert np.all(y <= 1e-9)
            ess = float(effective_sample_size(y).min())
            runs.append({"seconds": seconds, "ess": ess, "ess_per_second": ess / seconds})
        results["tmg_hmc"] = runs
    summary = {}
    for name, runs in results.items():
        med = {k: _median([r[k] for r in runs]) for k in ("seconds", "ess", "ess_per_second")}
        summary[name] = {"median": med, "runs": runs}
        print(f"{name:>16} {med['seconds']:>9.3f} {med['ess']:>8.1f} {med['ess_per_second']:>9.1f}")
    if "tmg_hmc" in summary:
        for name in samplers:
            ratio = (
                summary[name]["median"]["ess_per_second"]
                / summary["tmg_hmc"]["median"]["ess_per_second"]
            )
            summary[name]["ess_per_second_ratio_to_tmg_hmc"] = ratio
            print(f"  {name}: ESS/s ratio to tmg-hmc = {ratio:.2f}")
    return summary


def _ledges_throughput(args) -> dict:
    """Effective samples per second of HMC (default options) on three_ledges after 10 probes,
    one thread: --throughput-repeats runs of --throughput-samples samples with distinct seeds.

    Decision: one short run is a poor measurement of a rate: with 200 samples (16 chains of 13
    draws) the autocorrelation ESS of a single run scattered by 3x between seeds. The rate is
    the median over runs of ESS / seconds, reported with the spread of the ESS estimates."""
    problem, history, _ = three_ledges_after_probes(10, seed=args.seed)
    n, reps = args.throughput_samples, args.throughput_repeats
    print(f"\nthree_ledges after 10 probes, HMC throughput: {n} samples x {reps} runs")
    print(f"{'run':>4} {'chains':>6} {'seconds':>8} {'ESS':>7} {'ESS/s':>7}")
    runs = []
    for rep in range(reps):
        rng = np.random.default_rng(args.seed + 1000 * rep + 41)
        out = sample_posterior(problem.prior, history, n, rng)
        assert history_consistent(False, out.vertices, history, problem.friction).all()
        runs.append(
            {
                "samples": len(out.z),
                "chains": out.info["chains"],
                "seconds": out.seconds,
                "ess": out.ess,
                "ess_per_second": out.ess / out.seconds,
            }
        )
        r = runs[-1]
        print(
            f"{rep:>4} {r['chains']:>6} {r['seconds']:>8.3f} {r['ess']:>7.1f} "
            f"{r['ess_per_second']:>7.1f}"
        )
    ess = np.array([r["ess"] for r in runs])
    rate = np.array([r["ess_per_second"] for r in runs])
    summary = {
        "samples": n,
        "median_seconds": _median([r["seconds"] for r in runs]),
        "median_ess": float(np.median(ess)),
        "ess_min": float(ess.min()),
        "ess_max": float(ess.max()),
        "ess_relative_std": float(ess.std(ddof=1) / ess.mean()) if reps > 1 else 0.0,
        "median_ess_per_second": float(np.median(rate)),
        "ess_per_second_min": float(rate.min()),
        "ess_per_second_max": float(rate.max()),
    }
    print(
        f"median {summary['median_ess_per_second']:.1f} ESS/s (runs {rate.min():.1f} .. "
        f"{rate.max():.1f}); ESS {ess.min():.0f} .. {ess.max():.0f}, relative std "
        f"{100 * summary['ess_relative_std']:.0f} %"
    )
    return {"summary": summary, "runs": runs}


def _warm_start(args) -> dict:
    """The planner's case: 100 HMC samples on three_ledges after n probes, cold and warm-started
    (``init_z``) from 100 samples of the posterior before the last probe. Medians of seconds."""
    print("\nthree_ledges, 100 HMC samples after the last probe: cold vs warm start (init_z)")
    print(f"{'probes':>6} {'cold s':>8} {'warm s':>8} {'warm seeds':>10}")
    out = {}
    for n_probes in (5, 10, 15):
        problem, history, _ = three_ledges_after_probes(n_probes, seed=args.seed)
        before = history.subset(np.arange(len(history) - 2))  # without the last probe
        runs = []
        for rep in range(args.repeats):
            rng = np.random.default_rng(args.seed + 1000 * rep + 29)
            prev = sample_posterior(problem.prior, before, 100, rng)
            cold = sample_posterior(problem.prior, history, 100, rng)
            warm = sample_posterior(problem.prior, history, 100, rng, init_z=prev.z)
            for out_ in (cold, warm):
                assert history_consistent(False, out_.vertices, history, problem.friction).all()
            runs.append(
                {
                    "cold_seconds": cold.seconds,
                    "warm_seconds": warm.seconds,
                    "warm_seeds": warm.info["warm_seeds"],
                }
            )
        med = {k: _median([r[k] for r in runs]) for k in runs[0]}
        out[f"{n_probes}_probes"] = {"median": med, "runs": runs}
        print(
            f"{n_probes:>6} {med['cold_seconds']:>8.3f} {med['warm_seconds']:>8.3f} "
            f"{med['warm_seeds']:>10.0f}"
        )
    return out


def _posterior_check(args) -> dict:
    """Seeding check: Fig. 9 problem 2, HMC and Gibbs with default options over
    --check-seeds seeds against one long rejection run (20000 samples). Per run: the largest
    standardized error of the marginal vertex means, |mean - mean_ref| / std_ref, and the
    largest std ratio; per method: their maxima, the runs off by more than 0.3 std, the runs
    that re-seeded trapped chains and the runs that warned (``Convergence.converged``)."""
    problem, history = fig9_problem(2)
    shape = problem.prior
    ref = sample_posterior(shape, history, 20000, np.random.default_rng(12345), "rejection")
    ref_x = ref.vertices.reshape(len(ref.z), -1)
    mean, std = ref_x.mean(0), ref_x.std(0)
    n = args.check_samples
    print(f"\nFig. 9 problem 2: {n} samples x {args.check_seeds} seeds vs 20000 rejection draws")
    head = ("method", "max err", "> 0.3", "max std ratio", "reseeded", "warned")
    print(" ".join(f"{h:>{w}}" for h, w in zip(head, (7, 8, 6, 13, 8, 6), strict=True)))
    out = {}
    for method in ("hmc", "gibbs"):
        runs = []
        for seed in range(args.check_seeds):
            post = sample_posterior(shape, history, n, np.random.default_rng(seed), method)
            x = post.vertices.reshape(len(post.z), -1)
            runs.append(
                {
                    "seed": seed,
                    "mean_error": float(np.max(np.abs(x.mean(0) - mean) / std)),
                    "std_ratio": float(np.max(x.std(0) / std)),
                    "rhat": post.convergence.rhat,
                    "reseeded": post.convergence.reseeded,
                    "converged": post.convergence.converged,
                }
            )
        summary = {
            "max_mean_error": max(r["mean_error"] for r in runs),
            "runs_over_0.3": sum(r["mean_error"] > 0.3 for r in runs),
            "max_std_ratio": max(r["std_ratio"] for r in runs),
            "runs_reseeded": sum(r["reseeded"] > 0 for r in runs),
            "runs_warned": sum(not r["converged"] for r in runs),
        }
        out[method] = {"summary": summary, "runs": runs}
        print(
            f"{method:>7} {summary['max_mean_error']:>8.3f} {summary['runs_over_0.3']:>6} "
            f"{summary['max_std_ratio']:>13.2f} {summary['runs_reseeded']:>8} "
            f"{summary['runs_warned']:>6}"
        )
    return out


def run(args) -> dict:
    print("Posterior sampling benchmark (wall times on this machine; medians over repeats)")
    problems_out = {}
    for index in (1, 2, 3):
        problem, history = fig9_problem(index)
        problems_out[f"fig9_problem{index}"] = _run_problem(
            f"Fig. 9 problem {index} (sloper)",
            problem,
            history,
            args.samples,
            args,
            METHODS,
            args.max_draws,
        )
    problem, history, _ = three_ledges_after_probes(10, seed=args.seed)
    problems_out["three_ledges_10_probes"] = _run_problem(
        "three_ledges after 10 probes",
        problem,
        history,
        args.ledges_samples,
        args,
        METHODS,
        args.ledges_max_draws,
    )
    return {
        "problems": problems_out,
        "three_ledges_hmc_throughput": _ledges_throughput(args),
        "warm_start": _warm_start(args),
        "bridge": _bridge(args),
        "posterior_check": _posterior_check(args) if args.check_seeds > 0 else {},
    }
