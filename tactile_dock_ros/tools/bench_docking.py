"""Docking benchmark (paper Fig. 13, Sec. VI-A): ours vs growing window (GW) vs info gain (IG).

For each problem, ``--instances`` ground truths are drawn from the prior (seeded); every strategy
runs one episode per truth. Reported per problem and strategy: feasible count, success rate on
feasible truths, cycles on feasible truths (mean, std, max), outcomes on infeasible truths
(give-ups and their median cycles), and the wall time of one cycle (inference + planning):
median over all cycles, median over the cycles after each episode's first (those have a
history to condition on; first cycles plan on prior draws and take ~0.02 s, so they pull the
overall median down whenever most episodes dock at once), and the maximum. Episodes are the
repetitions, so ``--repeats`` is not used.
"""

from __future__ import annotations

import numpy as np

from ..core import explore, problems, simulate


def add_arguments(parser) -> None:
    parser.add_argument("--instances", type=int, default=20, help="ground truths per problem")
    parser.add_argument("--max-cycles", type=int, default=12, help="cycle cap per episode")
    parser.add_argument("--samples", type=int, default=100, help="posterior samples per cycle")
    parser.add_argument("--problems", nargs="+", default=problems.names(), choices=problems.names())
    parser.add_argument(
        "--strategies", nargs="+", default=list(explore.STRATEGIES), choices=explore.STRATEGIES
    )
    parser.add_argument("--quick", action="store_true", help="smoke run: 3 truths, cap 8")


def _summary(episodes: list[dict]) -> dict:
    feasible = [e for e in episodes if e["feasible"]]
    infeasible = [e for e in episodes if not e["feasible"]]
    cycles = np.array([e["cycles"] for e in feasible], float)
    cycle_times = [t for e in episodes for t in e["cycle_seconds"]]
    later_times = [t for e in episodes for t in e["cycle_seconds"][1:]]  # with a history
    give_up_cycles = [e["cycles"] for e in infeasible if e["outcome"] == "gave_up"]
    return {
        "instances": len(episodes),
        "feasible": len(feasible),
        "success_on_feasible": float(np.mean([e["docked"] for e in feasible]))
        if feasible
        else None,
        "cycles_mean": float(cycles.mean()) if len(cycles) else None,
        "cycles_std": float(cycles.std()) if len(cycles) else None,
        "cycles_max": int(cycles.max()) if len(cycles) else None,
        "infeasible_gave_up": len(give_up_cycles),
        "infeasible_give_up_cycles_median": float(np.median(give_up_cycles))
        if give_up_cycles
        else None,
        "errors": sum(e["outcome"] == "error" for e in episodes),
        "cycle_seconds_median": float(np.median(cycle_times)) if cycle_times else None,
        "later_cycle_seconds_median": float(np.median(later_times)) if later_times else None,
        "cycle_seconds_max": float(np.max(cycle_times)) if cycle_times else None,
    }


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def run(args) -> dict:
    instances, max_cycles = (3, 8) if args.quick else (args.instances, args.max_cycles)
    print(
        f"{'problem':13} {'strategy':8} {'feas':>5} {'succ':>5} {'cyc mean':>8} {'std':>5} "
        f"{'max':>4} {'inf gave up':>11} {'inf cyc':>7} {'err':>3} {'s/cycle':>7} {'later':>6} "
        f"{'max s':>6}"
    )
    results = []
    for name in args.problems:
        p_index = problems.names().index(name)  # seeds do not depend on the --problems subset
        problem = problems.get(name)
        truths = [
            problem.sample_ground_truth(np.random.default_rng([args.seed, p_index, i]))
            for i in range(instances)
        ]
        feasible = [simulate.feasible(problem, t) for t in truths]
        for strategy in args.strategies:
            episodes = []
            for i, (truth, ok) in enumerate(zip(truths, feasible, strict=True)):
                rng = np.random.default_rng([args.seed, p_index, i, 1])
                result = explore.run_episode(
                    problem, truth, strategy, rng, max_cycles, n_samples=args.samples
                )
                episodes.append(
                    {
                        "instance": i,
                        "feasible": bool(ok),
                        "outcome": result.outcome,
                        "docked": result.docked,
                        "cycles": result.cycles,
                        "message": result.message,
                        "cycle_seconds": [
                            c.inference_seconds + c.planning_seconds for c in result.cycles_log
                        ],
                    }
                )
            s = _summary(episodes)
            print(
                f"{name:13} {strategy:8} {s['feasible']:>2}/{s['instances']:<2} "
                f"{_fmt(s['success_on_feasible'], '.0%'):>5} {_fmt(s['cycles_mean'], '.2f'):>8} "
                f"{_fmt(s['cycles_std'], '.2f'):>5} {_fmt(s['cycles_max'], 'd'):>4} "
                f"{s['infeasible_gave_up']:>5}/{s['instances'] - s['feasible']:<5} "
                f"{_fmt(s['infeasible_give_up_cycles_median'], '.1f'):>7} {s['errors']:>3} "
                f"{_fmt(s['cycle_seconds_median'], '.3f'):>7} "
                f"{_fmt(s['later_cycle_seconds_median'], '.3f'):>6} "
                f"{_fmt(s['cycle_seconds_max'], '.2f'):>6}",
                flush=True,
            )
            results.append({"problem": name, "strategy": strategy, **s, "episodes": episodes})
    return {
        "instances": instances,
        "max_cycles": max_cycles,
        "samples": args.samples,
        "note": "wall times from a shared 2-core machine",
        "results": results,
    }
