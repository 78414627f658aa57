"""inference: the contact history and posterior shape samples (paper Sec. IV).

Subscribes ``terrain_prior`` (ShapeDistribution, latched), ``execution_report`` (only reports of the
current episode count; latched, so reports sent while this node was down arrive when it starts) and
``episode`` (std_msgs/UInt32, latched: the planner's episode id; a new id empties the history)
and ``episode_status`` (EpisodeStatus, latched: a report without its episode's nonce was not
sent for a plan of the planner and is dropped, ``watchdog.EpisodeGate.authentic``).
Keeps the history in a ``core.episode.EpisodeState`` (each row with the plan that observed it; the
previous posterior, the sampler's warm start), publishes it latched on ``contact_history`` (once an
episode id came) and, after every change while an episode runs, samples the posterior with
``core.episode_posterior.draw`` (up to ``num_samples`` draws on which every recorded compliant
slide could have happened under ``load_direction``, the planner's in both profiles; topped up
when the slides rule out most, and to ``give_up_draws`` when none lets an edge hold the load, so
that the planner's give-up reads "no hold in 3 / give_up_threshold draws") and publishes
``shape_samples`` (latched) and RViz markers on ``~/markers``.

Give-up check: the planner reads a give-up after a contact off at least its ``give_up_samples``
samples; on fewer it publishes a ``sample_request`` (SampleRequest) for the history it planned
on. This node then draws on from the samples it published (``core.episode_posterior.draw_on``,
the chains continuing on the same rows, to at most ``give_up_draws`` samples) and publishes
``shape_samples`` again for the same history. It answers once per episode and history length;
a request of another episode, without the episode's nonce, of another hold or history length,
or for no more samples than were published is refused (logged, no state changed).

Holds: every ``terrain_prior`` is kept by its ``hold_id`` (``core.holds.ReceivedPriors``, the
last ``max_holds``, as the planner keeps them); the episode samples on the hold its
``episode_status`` names (``EpisodeStatus.hold_id``; until that status came, the latest prior)
and ``shape_samples`` carry that ``hold_id``: the planner plans only on samples of its episode's
hold (the decision is in the planner's docstring). A node started after several captures
receives every kept hold, oldest first (``qos.priors``). Each replayed prior that moves the
selection (the latest, before the episode's status came) wakes the sampler; wake-ups coalesce
and a result overtaken by a newer prior is dropped unpublished (Threads, below), so a replay
costs no sampling per prior: when sampling is slower than the replay, one wasted call at most
(with an empty history, prior draws, sampling is cheap either way).

Restart without loss: with ``state_directory`` set, every report applied is journaled
(``nodes.journal``, ``<state_directory>/inference.jsonl``) before the history is published, and a
restarted node given the same episode id restores the history from it (docs/nodes.md). Each
posterior is saved there too (``nodes.warm_start``), so the restarted node, once the same prior
arrives, samples warm from it as the running node would have, not cold.

Threads (``main`` spins a MultiThreadedExecutor): the subscriptions (one mutually exclusive
group) only update the state under a lock and publish the history; sampling runs in a guard
condition's callback of its own group, so the node keeps taking reports, answering parameter
services and publishing the history while it samples. A result sampled on a history that
changed meanwhile is dropped and the newest history sampled instead. A wake-up for a state whose
samples are out samples nothing: under load one trigger was seen to run the callback twice,
which published a second set of the same history.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque
from functools import partial

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.time import Time
from std_msgs.msg import UInt32
from visualization_msgs.msg import MarkerArray

from tactile_dock_ros.core import descent_scan, episode_posterior, hmc_exit
from tactile_dock_ros.core.episode import EpisodeState
from tactile_dock_ros.core.history import History
from tactile_dock_ros.core.holds import ReceivedPriors
from tactile_dock_ros.core.sampling import NODE_METHODS
from tactile_dock_ros.execution.types import Report
from tactile_dock_ros.msg import (
    ContactHistory,
    EpisodeStatus,
    ExecutionReport,
    SampleRequest,
    ShapeDistribution,
    ShapeSamples,
)
from tactile_dock_ros.nodes import convert, journal, markers, qos, warm_start
from tactile_dock_ros.nodes.common import (
    LOAD_DIRECTION,
    MAX_HOLDS,
    PLANE_FRAME_ID,
    header,
    run,
    subscribe,
    unit_load,
)
from tactile_dock_ros.nodes.params import Param, declare
from tactile_dock_ros.nodes.watchdog import EpisodeGate

PARAMS = [
    PLANE_FRAME_ID,
    Param(
        "method",
        "hmc",
        "posterior sampler (not mh or gibbs: benchmark baselines that mix too slowly)",
        choices=NODE_METHODS,
    ),
    Param("num_samples", 100, "posterior samples per cycle", "", 2, 100000),
    Param(
        "give_up_draws",
        3000,
        "when no sample lets an edge hold the load after a contact, draw on to this many in all, "
        f"at most {episode_posterior.HOLD_ROW_DRAWS} / history rows (3 / the planner's "
        "give_up_threshold: none holding in that many bounds P(hold) below it at 95 %); also "
        "the most samples a sample_request gets; 0: off (requests refused)",
        "",
        0,
        100000,
    ),
    LOAD_DIRECTION,
    Param("seed", 0, "seed of the sampler's random generator", "", 0, 2**31 - 1),
    Param(
        "sampler_threads",
        2,
        "threads of the HMC exit search; the same samples in any count, shorter cycles where "
        "cores are free",
        "",
        1,
        64,
    ),
    Param("marker_samples", 20, "samples drawn as RViz line strips", "", 0, 1000),
    MAX_HOLDS,
    Param(
        "state_directory",
        "",
        "directory of the crash-safe history journal and the last posterior (warm start); "
        "empty: none (a restart loses the history)",
    ),
]
STASHED_REPORTS = 64  # reports of an episode id not (yet) current, kept until it arrives


class InferenceNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("inference", **kwargs)
        self.p = declare(self, PARAMS)
        self.load = unit_load(self.p)
        started = time.perf_counter()
        hmc_exit.warm_up()  # compiles on the first start after an install (~10 s), then cached
        descent_scan.warm_up()
        self.get_logger().info(
            f"sampler kernels ready in {time.perf_counter() - started:.1f} s (HMC exit search,"
            " descent line scan; compiled or cached)"
        )
        self.rng = np.random.default_rng(self.p.seed)
        self.priors = ReceivedPriors(self.p.max_holds)
        self.status_hold = (0, 0)  # (episode, hold_id) of the latest episode_status
        self.prior = None  # the prior sampled on (``select_prior``) and its hold id
        self.prior_hold = 0
        self.prior_fingerprint = ""  # ``warm_start.prior_fingerprint`` of ``prior``
        # the history with each row's plan, and the previous posterior (the warm start)
        self.episode_state = EpisodeState()
        self.frame_id = self.p.plane_frame_id
        self.handled_plans: set[int] = set()
        self.episode = 0
        self.gate = EpisodeGate()  # the planner's episode statuses: the nonces of reports
        self.past_episodes: set[int] = set()  # ids that ended here: a late copy is no new one
        self.stash: deque = deque(maxlen=STASHED_REPORTS)
        self.lock = threading.Lock()  # the state above, between subscriptions and the sampler
        self.generation = 0  # counts state changes; the sampler publishes only current results
        self.published = None  # (generation, posterior) of the last samples published
        self.request = None  # (generation, samples wanted in all): the planner's, to answer
        self.answered: set[tuple[int, int]] = set()  # (episode, history length) requested
        self.journal = journal.for_node(self.p.state_directory, "inference")
        self.saved_warm_start: warm_start.WarmStart | None = None  # read at restore, until used
        self.history_pub = self.create_publisher(ContactHistory, "contact_history", qos.LATCHED)
        self.samples_pub = self.create_publisher(ShapeSamples, "shape_samples", qos.LATCHED)
        self.marker_pub = self.create_publisher(MarkerArray, "~/markers", qos.LATCHED)
        inputs = MutuallyExclusiveCallbackGroup()
        self.sampler = self.create_guard_condition(self.sample, MutuallyExclusiveCallbackGroup())
        frame, priors = self.frame_id, qos.priors(self.p.max_holds)
        subscriptions = [
            (ShapeDistribution, "terrain_prior", self.on_prior, priors, frame),
            (ExecutionReport, "execution_report", self.on_report, qos.REPORTS, frame),
            (UInt32, "episode", self.on_episode, qos.LATCHED, None),
            (EpisodeStatus, "episode_status", self.on_episode_status, qos.LATCHED, None),
            (SampleRequest, "sample_request", self.on_sample_request, qos.EVENTS, None),
        ]
        for msg_type, topic, callback, profile, frame_id in subscriptions:
            subscribe(self, msg_type, topic, callback, profile, frame_id, callback_group=inputs)

    def on_prior(self, msg: ShapeDistribution) -> None:
        prior = convert.shape_from_msg(msg)
        stamp = Time.from_msg(msg.header.stamp).nanoseconds
        with self.lock:
            notes = self.priors.receive(msg.hold_id, stamp, prior)
            selected = self.select_prior()
            sampled = msg.hold_id == self.prior_hold and self.prior is not None
        for note in notes:
            self.get_logger().info(note)
        self.get_logger().info(
            f"prior of hold {msg.hold_id}: {prior.n_vertices} vertices, {prior.n_basis} basis "
            f"columns ({selected or ('the same again' if sampled else 'not the episode hold')})"
        )
        if sampled:  # sampled again, as on any input of the episode's
            self.changed()

    def select_prior(self) -> str | None:
        """Sample on the current episode's hold (the latest prior until its status came); under
        the lock. Returns None when that changed nothing, else what changed (for the log)."""
        episode, hold_id = self.status_hold
        wanted = hold_id if episode == self.episode else 0
        hold = self.priors.resolve(wanted)
        prior = None if hold is None else hold.prior
        fingerprint = "" if prior is None else warm_start.prior_fingerprint(prior)
        hold_id = wanted if hold is None else hold.hold_id
        if (hold_id, fingerprint) == (self.prior_hold, self.prior_fingerprint):
            return None
        same = fingerprint == self.prior_fingerprint
        if not same:  # z of another prior's basis: sample cold
            self.episode_state = dataclasses.replace(self.episode_state, warm_start=None)
        self.prior, self.prior_hold, self.prior_fingerprint = prior, hold_id, fingerprint
        self.adopt_saved_warm_start()
        if prior is None:
            return f"hold {hold_id} of episode {episode} not received: no samples"
        return f"sampling on hold {hold_id}" + (": the same prior, warm start kept" if same else "")

    def on_episode(self, msg: UInt32) -> None:
        episode = convert.episode_from_msg(msg)
        if episode == self.episode:
            return
        if episode in self.past_episodes:
            self.get_logger().warning(f"episode {episode} is over: ignored (late or resent)")
            return
        with self.lock:
            self.past_episodes.add(self.episode)
            self.episode = episode
            self.episode_state = EpisodeState()
            self.handled_plans.clear()
            self.answered.clear()
            restored = self.restore()
            self.adopt_saved_warm_start()
            selected = self.select_prior()
        if selected is not None:
            self.get_logger().info(selected)
        self.get_logger().info(
            f"episode {self.episode}: history restored from the journal, {restored} reports "
            f"({len(self.episode_state.history)} segments)"
            if restored
            else f"episode {self.episode}: history cleared"
        )
        stashed = [r for r in self.stash if r.episode == self.episode]
        for report in stashed:  # reports that arrived before the episode id
            self.stash.remove(report)
            self.apply(report)
        self.changed()

    def restore(self) -> int:
        """Reload the current episode's reports from the journal, or start a journal for it;
        the number of reports restored."""
        if self.journal is None:
            return 0
        records = self.journal.records
        if not records or records[0].get("episode") != self.episode:
            self.journal.reset([{"episode": self.episode}])
            return 0
        try:
            for record in records[1:]:
                self.add(record["plan_id"], History(record["a"], record["b"], record["status"]))
        except (KeyError, TypeError, ValueError) as err:
            self.get_logger().error(f"{self.journal.path}: bad record ({err}); history cleared")
            self.episode_state = EpisodeState()
            self.handled_plans.clear()
            self.journal.reset([{"episode": self.episode}])
            return 0
        try:
            self.saved_warm_start = warm_start.load(self.p.state_directory)
        except journal.JournalError as err:  # the history is restored: sample cold
            self.get_logger().error(f"{err}; sampling cold")
        return len(records) - 1

    def adopt_saved_warm_start(self) -> None:
        """Take the saved posterior (read by ``restore``) as the warm start once the prior is
        known, if it fits this episode, history and prior (``WarmStart.unusable``); under
        the lock."""
        saved = self.saved_warm_start
        if saved is None or self.prior is None or self.episode == 0:
            return
        self.saved_warm_start = None
        rows = len(self.episode_state.history)
        reason = saved.unusable(self.episode, rows, self.prior)
        if reason is not None:
            self.get_logger().info(f"saved posterior not used ({reason}): sampling cold")
            return
        try:
            self.episode_state = self.episode_state.sampled(saved.z, saved.dropped, saved.deferral)
        except ValueError as err:  # e.g. dropped or deferred rows outside the history
            self.get_logger().error(f"saved posterior not used ({err}): sampling cold")
            return
        self.get_logger().info(
            f"warm start restored: {len(saved.z)} posterior samples of {saved.history_length} "
            f"of the {rows} history rows, {len(saved.deferral)} of them deferred"
        )

    def on_episode_status(self, msg: EpisodeStatus) -> None:
        state, episode = convert.episode_status_from_msg(msg)
        with self.lock:
            self.gate.update(episode, state, int(msg.nonce))
            self.status_hold = (episode, int(msg.hold_id))
            selected = self.select_prior()
        if selected is not None:
            self.get_logger().info(selected)
            self.changed()

    def on_report(self, msg: ExecutionReport) -> None:
        report = convert.report_from_msg(msg)
        with self.lock:
            authentic = self.gate.authentic(report.episode, report.nonce)
        if not authentic:
            raise convert.MessageError(
                f"report of plan {report.plan_id} of episode {report.episode} without the "
                "episode's nonce (not a report of a plan the planner sent)"
            )
        if report.episode != self.episode:
            self.stash.append(report)  # maybe an episode whose id has not arrived yet
            self.get_logger().warning(
                f"plan {report.plan_id} of episode {report.episode}: report set aside (the "
                f"current episode is {self.episode})"
            )
            return
        if self.apply(report):
            self.changed()

    def on_sample_request(self, msg: SampleRequest) -> None:
        """Draw on for the planner's give-up check (module docstring); a refusal raises
        MessageError (logged and counted by ``subscribe``) before any state changes."""
        request = convert.sample_request_from_msg(msg)
        episode, rows = request["episode"], request["history_length"]
        wanted = min(request["num_samples"], self.p.give_up_draws)
        with self.lock:
            refusal = self.request_refusal(request, wanted)
            if refusal is None:
                self.request = (self.generation, wanted)
                self.answered.add((episode, rows))
        if refusal is not None:
            raise convert.MessageError(f"sample request refused: {refusal}")
        self.get_logger().info(
            f"episode {episode}: the planner asks for {request['num_samples']} samples of "
            f"{rows} history rows before giving up: drawing on to {wanted}"
        )
        self.sampler.trigger()

    def request_refusal(self, request: dict, wanted: int) -> str | None:
        """Why a sample request (``convert.sample_request_from_msg``) for ``wanted`` samples in
        all is refused, None when it is answered; under the lock."""
        episode, rows = request["episode"], request["history_length"]
        published = self.published
        if not self.gate.authentic(episode, request["nonce"]):
            return f"episode {episode} without the episode's nonce"
        if episode != self.episode or rows != len(self.episode_state.history):
            return (
                f"it is for episode {episode} with {rows} history rows, the current is "
                f"{self.episode} with {len(self.episode_state.history)}"
            )
        if request["hold_id"] != self.prior_hold:
            return f"it is for hold {request['hold_id']}, sampling is on {self.prior_hold}"
        if (episode, rows) in self.answered:
            return "that history was drawn on already"
        if published is None or published[0] != self.generation:
            return "its samples are not the latest published (a newer set is coming)"
        if wanted <= len(published[1].z):
            return (
                f"{len(published[1].z)} samples were published, give_up_draws is "
                f"{self.p.give_up_draws}"
            )
        return None

    def apply(self, report: Report) -> bool:
        """Add a report of the current episode to the history (journaled first); False for a
        duplicate or late one (the executor's reports are latched: a restart receives them
        again) and for one without segments. Decision: a report without segments (an ABORTED
        or refused plan's) is no evidence and changes no state: a refusal of a plan the planner
        did not send (its id, maybe far ahead) must not make the real reports late."""
        if not len(report.history):
            self.get_logger().info(f"plan {report.plan_id}: report without evidence, not recorded")
            return False
        if report.plan_id <= max(self.handled_plans, default=0):  # plans run one at a time
            self.get_logger().info(f"plan {report.plan_id}: duplicate or late report ignored")
            return False
        new = report.history
        if self.journal is not None:
            record = {"plan_id": report.plan_id, "a": new.a.tolist(), "b": new.b.tolist()}
            try:
                self.journal.append({**record, "status": new.status.tolist()})
            except journal.JournalError as err:  # go on: the history is still in memory
                self.get_logger().error(f"journal: {err}; a restart would lose this report")
        with self.lock:
            self.add(report.plan_id, new)
        return True

    def add(self, plan_id: int, new: History) -> None:
        self.episode_state = self.episode_state.record(new, plan_id)
        self.handled_plans.add(plan_id)

    def changed(self) -> None:
        """Publish the episode's history now and wake the sampler (its own thread); nothing
        before an episode id came (a restarted node would publish an empty history)."""
        with self.lock:
            self.generation += 1
            state, frame_id = self.episode_state, self.frame_id
        if self.episode == 0:
            return
        self.history_pub.publish(convert.history_to_msg(state, header(self, frame_id)))
        self.sampler.trigger()

    def sample(self) -> None:
        """Sample and publish the posterior of the current history (the guard condition's
        callback); a result overtaken by a newer history is dropped (that one is sampled)."""
        with self.lock:
            generation, prior, state = self.generation, self.prior, self.episode_state
            hold_id = self.prior_hold
            fingerprint = self.prior_fingerprint
            episode, cycle, frame_id = self.episode, len(self.handled_plans) + 1, self.frame_id
            request, self.request = self.request, None
            published = self.published
        if prior is None or episode == 0:
            return
        history = state.history
        drawing_on = (
            request is not None
            and published is not None
            and request[0] == published[0] == generation
        )
        if not drawing_on and published is not None and published[0] == generation:
            return  # this state's samples are out: a second wake-up for one trigger
        try:
            if drawing_on:  # the planner's give-up check: the published set and more
                previous = published[1]
                posterior = episode_posterior.draw_on(
                    prior, state, previous, request[1] - len(previous.z), self.rng, self.load,
                    method=self.p.method, threads=self.p.sampler_threads,
                )  # fmt: skip
            else:
                posterior = episode_posterior.draw(
                    prior, state, self.p.num_samples, self.rng, self.load,
                    method=self.p.method, threads=self.p.sampler_threads,
                    hold_draws=self.p.give_up_draws,
                )  # fmt: skip
        except (ValueError, RuntimeError) as err:  # e.g. no state consistent with the history
            self.get_logger().error(f"posterior sampling failed: {err}")
            posterior = previous if drawing_on else None  # the planner gets its answer
        with self.lock:
            if generation != self.generation:
                return  # the state changed while sampling: the newer trigger resamples
            if posterior is not None:
                self.episode_state = state.sampled(
                    posterior.z, posterior.dropped, posterior.deferral
                )
                self.published = (generation, posterior)
        if posterior is not None and self.journal is not None:
            self.save_warm_start(episode, len(history), fingerprint, posterior)
        if posterior is None or len(posterior.vertices) < 2:
            # the planner needs two (moment fit); tell it there are none
            count = 0 if posterior is None else len(posterior.vertices)
            self.get_logger().error(f"{count} posterior samples: publishing an empty set")
            self.samples_pub.publish(
                convert.samples_to_msg(
                    np.zeros((0, prior.n_vertices, 2)),
                    header(self, frame_id),
                    self.p.method,
                    0.0,
                    len(history),
                    hold_id=hold_id,
                )
            )
            return
        stamp = header(self, frame_id)
        self.samples_pub.publish(
            convert.samples_to_msg(
                posterior.vertices,
                stamp,
                posterior.method,
                posterior.ess,
                len(history),
                posterior.ignored,  # the planner leaves dropped and deferred rows out alike
                posterior.seconds,
                hold_id,
            )
        )
        self.marker_pub.publish(
            markers.samples_and_history(posterior.vertices[: self.p.marker_samples], history, stamp)
        )
        self.get_logger().info(
            f"episode {episode} cycle {cycle}: history {len(history)} segments, "
            f"{len(posterior.vertices)} {posterior.method} samples, ESS {posterior.ess:.1f}, "
            f"R-hat {posterior.convergence.rhat:.3f}, "
            f"{posterior.seconds:.3f} s, dropped {len(posterior.dropped)}, "
            f"deferred {len(posterior.deferred)}, "
            f"{posterior.info['slide_rejected']} of {posterior.info['slide_draws']} draws ruled "
            "out by slides" + (", drawn on for the planner's give-up check" if drawing_on else "")
        )
        check = posterior.convergence
        if check.reseeded or not check.converged:
            self.get_logger().warning(
                f"posterior chains disagreed: {check.reseeded} trapped chains re-seeded in "
                f"{check.rounds} rounds ({check.mass_rounds} chosen by posterior mass), "
                f"{check.trapped} still trapped, split R-hat "
                f"{check.rhat:.3f} (limit {check.rhat_limit:.3f})"
            )

    def save_warm_start(self, episode: int, rows: int, fingerprint: str, posterior) -> None:
        """Save the posterior for a restart (``nodes.warm_start``); a failure is logged, the
        node goes on (a restart would then sample cold)."""
        saved = warm_start.WarmStart(
            episode, rows, fingerprint, posterior.z, posterior.dropped, posterior.deferral
        )
        try:
            warm_start.save(self.p.state_directory, saved)
        except journal.JournalError as err:
            self.get_logger().error(f"warm start: {err}; a restart would sample cold")


class DrainingExecutor(MultiThreadedExecutor):
    """A MultiThreadedExecutor whose ``shutdown`` first lets the callbacks already handed to its
    threads finish (a running sampler too), then shuts down as rclpy does.

    Decision: rclpy's ``Executor.shutdown`` destroys the executor's guard condition before
    ``MultiThreadedExecutor.shutdown`` joins the threads, and a callback handler a thread starts
    after that fails on that guard (``gc.trigger()``) before the callback runs. The error stays
    in the handler's Task, which nobody reads once spinning stopped, and is printed at exit:
    "The following exception was never retrieved: cannot use Destroyable because destruction
    was requested" (seen on SIGINT while reports arrived and the sampler ran). Nothing spins
    while ``shutdown`` runs, so draining the thread pool first hands out no new work."""

    def shutdown(self, timeout_sec: float | None = None, **kwargs) -> bool:
        self._executor.shutdown(wait=kwargs.get("wait_for_threads", True))
        return super().shutdown(timeout_sec, **kwargs)


def main(args: list[str] | None = None) -> int:
    # Three threads: the inputs, the sampler and the default group (parameter services).
    return run(InferenceNode, args, partial(DrainingExecutor, num_threads=3))
