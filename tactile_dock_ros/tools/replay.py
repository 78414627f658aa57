"""Replay a recorded docking episode offline: re-plan every cycle from what the planner had.

    python -m tactile_dock_ros.tools.replay BAG [--config config/robot.yaml]
        [--give-up-threshold P] [--contact-resolution M] [--compliant | --no-compliant]
        [--resample N [--method hmc] [--seed S]] [--png cycles.png] [--json replay.json]

BAG is a rosbag2 directory with the topics of ``tools.bag.EPISODE_TOPICS`` (record them on the
robot with ``ros2 bag record``; ``make demo DEMO_ARGS="--bag DIR"`` records the mock episode).
For each recorded plan (one per cycle; the planner's resent copies are skipped) the planner
node's inputs are rebuilt: the prior, the posterior samples it planned with and its
``core.episode.EpisodeState``: the contact history (samples and history of the plan's
``history_length`` stamped last before it, ``load_cycles``), the tool position (the plan's first
waypoint) and the aim points of the episode's earlier plans (eq. 24). Then
``core.planner.plan`` runs again with the planner parameters of ``--config`` (the parameter
file the robot ran with; the planner node's defaults otherwise), the load direction and motion
model of the recorded plan, and any override given here. A relative ``--config`` path that does
not exist from the working directory is taken from the installed package share
(``tools.package_files``: ``config/robot.yaml`` works from a colcon workspace too); the file
used is logged. The planner is
deterministic: with the recorded parameters every replayed plan equals the recorded one, so a
difference means the code or a parameter changed. ``--resample N`` plans with N fresh posterior
samples instead (``core.episode_posterior.draw`` as the inference node draws them, from the
prior and history, cold-started, seeded: no row dropped yet, the samples conditioned on the
recorded slides under the plan's load), which separates inference noise from planning. Exit
status 0 when every cycle was replayed.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import yaml

from ..core import episode_posterior, planner
from ..core.episode import EpisodeState, PlannerConfig
from ..core.sampling import METHODS
from ..core.shape import GaussianShape
from . import bag, figures, package_files

PATH_TOLERANCE_M = 1e-9  # replayed and recorded paths "agree" below this


@dataclass(frozen=True)
class Cycle:
    """What the planner node had when it published one recorded plan."""

    episode: int  # the planner's episode id
    prior: GaussianShape
    # history with each row's plan, the rows inference dropped for ``samples``
    # (dropped_segments), aim points of the episode's earlier DOCK plans, tool position (the
    # plan's first waypoint)
    state: EpisodeState
    samples: np.ndarray  # (N, n, 2) posterior vertices the node planned with
    recorded: object  # execution.types.PlanCommand
    outcome: str  # the executor's report for the plan ("-": none recorded)


@dataclass(frozen=True)
class Settings:
    """Planner settings of the replay: the planner node's (``planner_node.planner_config``)."""

    config: PlannerConfig  # its load is replaced by each recorded plan's
    compliant: bool | None  # None: as recorded in each plan


def _stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def _pick(items: list, span: tuple[int, int], stamp_ns: int):
    """Of ``items`` [(bag position, header stamp ns, value)] recorded within the episode's
    ``span`` of bag positions, the one stamped last at or before ``stamp_ns``, else (clocks
    that disagree) the first recorded in the span; (value, stamped after) or (None, False).

    Decision: header stamps within the episode, not bag order: a recorder orders the messages
    of one topic, not across topics, so samples may be recorded after the plan made from them;
    the span keeps another episode's history of the same length out."""
    inside = [(t, value) for position, t, value in items if span[0] <= position < span[1]]
    before = [(t, i) for i, (t, _) in enumerate(inside) if t <= stamp_ns]
    if before:
        return inside[max(before)[1]][1], False
    return (inside[0][1], True) if inside else (None, False)


def _episode_spans(plans: list) -> dict[int, tuple[int, int]]:
    """Bag positions of each episode's messages: from after the previous episode's last plan
    to the next episode's first plan (the last episode: to the bag's end)."""
    firsts, lasts = {}, {}
    for position, _, command in plans:
        firsts.setdefault(command.episode, position)
        lasts[command.episode] = position
    order = sorted(firsts, key=firsts.get)
    spans = {}
    for k, episode in enumerate(order):
        start = lasts[order[k - 1]] + 1 if k else 0
        end = firsts[order[k + 1]] if k + 1 < len(order) else 2**62
        spans[episode] = (start, end)
    return spans


def load_cycles(path: Path, log=print) -> list[Cycle]:
    """The cycles of every episode in the bag at ``path``, in order.

    A plan's inputs are the ``/contact_history`` and ``/shape_samples`` of the length the plan
    records (``DockingPlan.history_length``), recorded within its episode and each stamped last
    at or before the plan (``_pick``), and the prior of the hold the samples name
    (``ShapeSamples.hold_id``), stamped last at or before the plan; a captured hold's since the
    bag's start (it may predate earlier episodes), hold 0 (no captured hold) within the episode.
    Raises ``bag.BagError`` when the bag cannot be read or holds no plan with its inputs.
    """
    from ..nodes import convert

    priors: dict[int, list] = {}  # hold id -> [(position, stamp, GaussianShape)]
    histories: dict[int, list] = {}  # length -> [(position, stamp, EpisodeState)]
    samples: dict[int, list] = {}  # history length -> [(position, stamp, (vertices, dropped))]
    reports: dict[tuple[int, int], str] = {}  # (episode, plan_id) -> outcome name
    plans, seen = [], set()
    for position, (topic, _, msg) in enumerate(bag.read(path)):
        entry = (position, _stamp_ns(msg)) if hasattr(msg, "header") else (position, 0)
        if topic == "/terrain_prior":
            priors.setdefault(int(msg.hold_id), []).append((*entry, convert.shape_from_msg(msg)))
        elif topic == "/contact_history":
            state = convert.history_from_msg(msg)
            histories.setdefault(len(state.history), []).append((*entry, state))
        elif topic == "/shape_samples" and msg.num_samples > 0:
            dropped = np.array(msg.dropped_segments, int)
            value = (convert.samples_from_msg(msg), dropped, int(msg.hold_id))
            samples.setdefault(int(msg.history_length), []).append((*entry, value))
        elif topic == "/execution_report":
            report = convert.report_from_msg(msg)
            reports[(report.episode, report.plan_id)] = report.outcome_name
        elif topic == "/plan":
            key = (msg.plan_id, msg.header.stamp.sec, msg.header.stamp.nanosec)
            if key not in seen:  # the planner resends a plan until its report arrives
                seen.add(key)
                plans.append((*entry, convert.plan_from_msg(msg)))
    spans = _episode_spans(plans)
    cycles, episode, targets = [], None, []
    for _, stamp, command in plans:
        if command.episode != episode:
            episode, targets = command.episode, []
        previous = np.array(targets).reshape(-1, 2)
        if command.dock:
            targets = [*targets, command.target_point]
        name = f"episode {episode} plan {command.plan_id}"
        length = command.history_length
        picked = [
            _pick(items, spans[episode], stamp)
            for items in (histories.get(length, []), samples.get(length, []))
        ]
        (recorded, _), (drawn, _) = picked
        hold = 0 if drawn is None else drawn[2]
        span = spans[episode] if hold == 0 else (0, spans[episode][1])
        picked.append(_pick(priors.get(hold, []), span, stamp))
        prior = picked[-1][0]
        if prior is None or recorded is None or drawn is None:
            log(f"{name}: skipped, its prior, history or samples (length {length}) are missing")
            continue
        if any(late for _, late in picked):
            log(f"{name}: an input is stamped after the plan (clocks differ?); used the first")
        if len(command.waypoints) == 0:
            log(f"{name}: skipped, no tool position")
            continue
        outcome = reports.get((episode, command.plan_id), "-")
        vertices, dropped, _ = drawn
        state = replace(recorded, dropped=dropped, targets=previous, tool=command.waypoints[0])
        cycles.append(Cycle(episode, prior, state, vertices, command, outcome))
    if not cycles:
        raise bag.BagError(f"{path}: no plan with its inputs recorded (topics: /plan, ...)")
    return cycles


def replan(cycle: Cycle, settings: Settings, fresh=None) -> planner.Plan:
    """``core.planner.plan`` on the cycle's inputs, or on ``fresh`` posterior samples
    (``core.sampling.PosteriorSamples``) instead of the recorded ones."""
    compliant = cycle.recorded.compliant if settings.compliant is None else settings.compliant
    config = replace(settings.config, load=cycle.recorded.load, compliant=compliant)
    if fresh is None:
        return planner.plan(cycle.samples, cycle.prior, cycle.state, config)
    state = cycle.state.sampled(dropped=fresh.dropped, deferral=fresh.deferral)
    return planner.plan(fresh.vertices, cycle.prior, state, config)


def compare(cycle: Cycle, plan: planner.Plan) -> dict:
    """Recorded vs replayed decision, target edge, P_dock and path of one cycle."""
    recorded = cycle.recorded
    decision = "dock" if recorded.dock else "give_up"
    same = decision == plan.decision and abs(recorded.p_dock - plan.p_dock) <= 1e-9
    if same and plan.decision == "dock":
        same = (
            recorded.target_edge == plan.target_edge
            and recorded.waypoints.shape == plan.path.shape
            and np.allclose(recorded.waypoints, plan.path, rtol=0.0, atol=PATH_TOLERANCE_M)
        )
    return {
        "episode": cycle.episode,
        "plan_id": recorded.plan_id,
        "history_segments": len(cycle.state.history),
        "recorded": {
            "decision": decision,
            "target_edge": recorded.target_edge,
            "p_dock": recorded.p_dock,
            "outcome": cycle.outcome,
        },
        "replayed": {
            "decision": plan.decision,
            "target_edge": plan.target_edge,
            "p_dock": float(plan.p_dock),
            "reason": plan.reason,
            "rejected_samples": plan.rejected,
        },
        "same": bool(same),
    }


def settings_from(args: argparse.Namespace) -> Settings:
    """Planner parameters: node defaults < ``--config`` file < command-line overrides (of
    ``give_up_threshold``, ``contact_resolution``); the load and motion model come from each
    recorded plan in ``replan`` (the motion model unless ``--compliant`` is given)."""
    from ..nodes.planner_node import CONFIG_SETTINGS, PARAMS, planner_config

    table = {p.name: p for p in PARAMS}
    values = {name: table[name].default for name in CONFIG_SETTINGS}
    if args.config is not None:
        path = package_files.resolve(args.config)  # FileNotFoundError names where it looked
        document = yaml.safe_load(path.read_text()) or {}
        for section in ("/**", "planner", "/planner"):
            values.update(
                {
                    k: v
                    for k, v in (document.get(section) or {}).get("ros__parameters", {}).items()
                    if k in values
                }
            )
    for name in ("give_up_threshold", "contact_resolution"):
        if getattr(args, name) is not None:
            values[name] = getattr(args, name)
    for name, value in values.items():
        table[name].check(value)  # the node's own range check
    return Settings(planner_config(SimpleNamespace(**values)), args.compliant)


def render(cycles: list[Cycle], plans: list[planner.Plan], path: Path) -> None:
    """One panel per cycle: samples (grey), history, recorded path (blue), replayed (orange)."""
    plt = figures.pyplot()
    cols = min(3, len(cycles))
    rows = int(np.ceil(len(cycles) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 4.5 * rows), squeeze=False)
    for ax in axes.ravel()[len(cycles) :]:
        ax.axis("off")
    for ax, cycle, plan in zip(axes.ravel(), cycles, plans, strict=False):
        for vertices in cycle.samples[:30]:
            figures.outline(ax, vertices, cycle.prior.closed, color="0.6", lw=0.5, alpha=0.5)
        figures.history(ax, cycle.state.history)
        if cycle.recorded.dock:
            ax.plot(*cycle.recorded.waypoints.T, color="tab:blue", lw=2.0, label="recorded")
        if plan.decision == "dock":
            ax.plot(*plan.path.T, "--", color="tab:orange", lw=1.5, label="replayed")
        ax.plot(*cycle.state.tool, "k.", ms=8)
        ax.set_title(
            f"episode {cycle.episode} plan {cycle.recorded.plan_id}: recorded P_dock "
            f"{cycle.recorded.p_dock:.2f} -> {cycle.outcome}\nreplayed {plan.decision} "
            f"P_dock {plan.p_dock:.2f}",
            fontsize=9,
        )
        ax.set_aspect("equal")
    axes.ravel()[0].legend(loc="best", fontsize=8)
    figures.save(fig, path)


def _format(row: dict) -> str:
    rec, rep = row["recorded"], row["replayed"]
    mark = "same" if row["same"] else "DIFFERENT"
    return (
        f"episode {row['episode']} plan {row['plan_id']} ({row['history_segments']} segments): "
        f"recorded {rec['decision']} edge {rec['target_edge']} P_dock={rec['p_dock']:.3f} -> "
        f"{rec['outcome']}; replayed {rep['decision']} edge {rep['target_edge']} "
        f"P_dock={rep['p_dock']:.3f} [{mark}]"
        + ("" if rep["decision"] == "dock" else f" ({rep['reason']})")
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tactile_dock_ros.tools.replay",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("bag", type=Path, help="rosbag2 directory")
    parser.add_argument(
        "--config",
        type=Path,
        help="parameter file the planner node ran with; a relative path missing here is taken "
        "from the installed package share (e.g. config/robot.yaml)",
    )
    parser.add_argument("--give-up-threshold", type=float, help="override (probability)")
    parser.add_argument("--contact-resolution", type=float, help="override, metres (w, eq. 24)")
    parser.add_argument(
        "--compliant",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="override the motion model (default: as recorded in each plan)",
    )
    parser.add_argument(
        "--resample",
        type=int,
        default=0,
        metavar="N",
        help="plan on N fresh posterior samples (as inference draws them)",
    )
    parser.add_argument("--method", default="hmc", choices=METHODS)
    parser.add_argument("--seed", type=int, default=0, help="seed of --resample")
    parser.add_argument("--png", type=Path, help="write one panel per cycle")
    parser.add_argument("--json", type=Path, help="write the comparison as JSON")
    args = parser.parse_args(argv)
    if args.resample < 0 or args.resample == 1:
        parser.error("--resample needs N >= 2 samples (the planner fits their moments)")
    try:
        settings = settings_from(args)
        cycles = load_cycles(args.bag)
    except (bag.BagError, ValueError, OSError) as err:
        print(f"replay: {err}", file=sys.stderr)
        return 2
    print(
        f"{len(cycles)} recorded plans; give_up_threshold {settings.config.give_up_threshold:g}, "
        f"contact_resolution {settings.config.contact_resolution:g} m"
    )
    rng = np.random.default_rng(args.seed)
    rows, plans = [], []
    for cycle in cycles:
        fresh = None
        if args.resample:
            cold = replace(cycle.state, dropped=(), warm_start=None, deferral=None)
            load = cycle.recorded.load
            fresh = episode_posterior.draw(
                cycle.prior, cold, args.resample, rng, load, method=args.method,
                hold_draws=planner.give_up_draws(settings.config.give_up_threshold),
            )  # fmt: skip
        plans.append(replan(cycle, settings, fresh))
        rows.append(compare(cycle, plans[-1]))
        print(_format(rows[-1]))
    print(f"{sum(r['same'] for r in rows)}/{len(rows)} cycles replayed to the same plan")
    if args.png is not None:
        render(cycles, plans, args.png)
        print(f"wrote {args.png}")
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=2))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
