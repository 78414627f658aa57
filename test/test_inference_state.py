"""The inference node's state across restarts (its journal) and while it samples (threads).

In-process nodes over DDS (random domain, conftest): a restarted node, in a fresh context where
no report is redelivered, restores the episode's history from its journal alone; and the node
takes reports and publishes the history while a sampling call is still running.
"""

import dataclasses
import threading
from functools import partial

import numpy as np
import pytest
from node_helpers import launch_nodes, node_with_driver
from rclpy.executors import MultiThreadedExecutor
from ros_helpers import spin_until
from std_msgs.msg import UInt32
from tactile_dock_ros.msg import ContactHistory, ExecutionReport, ShapeDistribution, ShapeSamples

from tactile_dock_ros.core import problems, sampling, slides
from tactile_dock_ros.core.sampling import Deferral
from tactile_dock_ros.execution.types import Report
from tactile_dock_ros.nodes import convert, inference_node, qos, warm_start

pytestmark = pytest.mark.dds
EPISODE = 41


def _report(plan_id: int, rows: int) -> ExecutionReport:
    rng = np.random.default_rng(plan_id)
    a = rng.uniform(-0.2, 0.2, size=(rows, 2))
    history = convert.history_from_segments([]).extend(a, a + np.array([0.0, -0.05]), [0] * rows)
    report = Report(plan_id, ExecutionReport.NO_CONTACT, history, a[-1], "", EPISODE)
    return convert.report_to_msg(report, convert.Header(frame_id="dock_plane"))


def _inputs(driver):
    """Latched episode id and the executor's report topic, as the suite has them."""
    episode = driver.create_publisher(UInt32, "episode", qos.LATCHED)
    reports = driver.create_publisher(ExecutionReport, "execution_report", qos.REPORTS)
    return episode, reports


def test_a_restarted_node_restores_the_episode_history_from_its_journal(tmp_path):
    spec = launch_nodes("mock", state_directory=str(tmp_path / "state"))["inference"]
    with node_with_driver(spec, tmp_path) as (node, driver, executor):
        episode, reports = _inputs(driver)
        assert spin_until(executor, lambda: reports.get_subscription_count() > 0, 10.0)
        episode.publish(UInt32(data=EPISODE))
        assert spin_until(executor, lambda: node.episode == EPISODE, 10.0)
        for plan_id, rows in ((1, 2), (2, 3)):
            reports.publish(_report(plan_id, rows))
        assert spin_until(executor, lambda: len(node.episode_state.history) == 5, 10.0)
        before = node.episode_state
    # A new process: only the latched episode id arrives again (no report is redelivered).
    with node_with_driver(spec, tmp_path) as (node, driver, executor):
        histories = []
        driver.create_subscription(ContactHistory, "contact_history", histories.append, qos.LATCHED)
        episode, _ = _inputs(driver)
        episode.publish(UInt32(data=EPISODE))
        assert spin_until(executor, lambda: histories and len(histories[-1].segments) == 5, 10.0)
        restored = convert.history_from_segments(histories[-1].segments)
        np.testing.assert_array_equal(restored.a, before.history.a)  # bit-exact through JSON
        np.testing.assert_array_equal(restored.b, before.history.b)
        np.testing.assert_array_equal(restored.status, before.history.status)
        np.testing.assert_array_equal(node.episode_state.move_ids, [1, 1, 2, 2, 2])
        assert node.handled_plans == {1, 2}
        # A report already in the journal is a duplicate; another episode starts empty.
        _, reports = _inputs(driver)
        reports.publish(_report(2, 3))
        assert not spin_until(executor, lambda: len(node.episode_state.history) != 5, 1.0)
        episode.publish(UInt32(data=EPISODE + 1))
        assert spin_until(executor, lambda: len(node.episode_state.history) == 0, 10.0)


def test_a_restarted_node_samples_warm_from_its_saved_posterior(tmp_path, monkeypatch):
    """The posterior of the killed node's last cycle is the restarted node's warm start once
    the same prior and episode id arrive (no report redelivered), with its deferred rows; the
    same prior sent again keeps the warm start, another prior drops it."""
    spec = launch_nodes("mock", state_directory=str(tmp_path / "state"))["inference"]
    args = ["-p", "inference:num_samples:=8"]
    with node_with_driver(spec, tmp_path, args) as (node, driver, executor):
        samples = []
        driver.create_subscription(ShapeSamples, "shape_samples", samples.append, qos.LATCHED)
        prior = driver.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED)
        episode, reports = _inputs(driver)
        assert spin_until(executor, lambda: reports.get_subscription_count() > 0, 10.0)
        prior.publish(_prior_msg())
        episode.publish(UInt32(data=EPISODE))
        reports.publish(_report(1, 2))
        assert spin_until(executor, lambda: samples and samples[-1].history_length == 2, 30.0)
        saved = node.episode_state.warm_start
    assert saved is not None and len(saved) == 8
    # as if the killed node's seed search had deferred row 1: the snapshot carries it
    state_dir = tmp_path / "state"
    snapshot = warm_start.load(state_dir)
    untried = np.random.default_rng(3).standard_normal((2, snapshot.z.shape[1]))
    deferral = Deferral(np.array([1]), np.array([2]), untried)
    warm_start.save(state_dir, dataclasses.replace(snapshot, deferral=deferral))

    starts, deferrals = [], []  # init_z and deferral of every call of the restarted node

    def recording_sampler(prior, history, *args, init_z=None, deferral=None, **kwargs):
        starts.append(init_z)
        deferrals.append(deferral)
        return real_sampler(prior, history, *args, init_z=init_z, deferral=deferral, **kwargs)

    real_sampler = sampling.sample_posterior
    monkeypatch.setattr(sampling, "sample_posterior", recording_sampler)
    with node_with_driver(spec, tmp_path, args) as (node, driver, executor):
        prior = driver.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED)
        episode, _ = _inputs(driver)
        prior.publish(_prior_msg())
        episode.publish(UInt32(data=EPISODE))
        assert spin_until(executor, lambda: starts, 30.0)
        np.testing.assert_array_equal(starts[0], saved)  # bit-exact, not a cold start
        restored = deferrals[0]  # the search goes on where it stopped, its effort kept
        np.testing.assert_array_equal(restored.rows, [1])
        np.testing.assert_array_equal(restored.effort, [2])
        np.testing.assert_array_equal(restored.starts, untried)
        prior.publish(_prior_msg())  # re-delivered (e.g. perception restarted): kept
        assert spin_until(executor, lambda: len(starts) >= 2, 30.0)
        assert starts[1] is not None
        prior.publish(_prior_msg("notch"))
        assert spin_until(executor, lambda: len(starts) >= 3, 30.0)
        assert starts[2] is None


def test_the_node_takes_reports_while_it_samples(tmp_path, monkeypatch):
    """The first sampling call blocks until released: meanwhile a second report is taken and
    its history published; the overtaken result is dropped, the full history sampled."""
    release, calls = threading.Event(), []

    def blocking_sampler(prior, history, *args, **kwargs):
        calls.append(len(history))
        if len(calls) == 1:
            assert release.wait(20.0), "the test never released the sampler"
        return real_sampler(prior, history, *args, **kwargs)

    real_sampler = sampling.sample_posterior
    monkeypatch.setattr(sampling, "sample_posterior", blocking_sampler)
    spec = launch_nodes("mock")["inference"]
    threads = partial(MultiThreadedExecutor, num_threads=3)  # as inference_node.main runs it
    with node_with_driver(spec, tmp_path, ["-p", "inference:num_samples:=4"], threads) as (
        _, driver, executor,
    ):  # fmt: skip
        histories, samples = [], []
        driver.create_subscription(ContactHistory, "contact_history", histories.append, qos.LATCHED)
        driver.create_subscription(ShapeSamples, "shape_samples", samples.append, qos.LATCHED)
        prior = driver.create_publisher(type(_prior_msg()), "terrain_prior", qos.LATCHED)
        episode, reports = _inputs(driver)
        assert spin_until(executor, lambda: reports.get_subscription_count() > 0, 10.0)
        prior.publish(_prior_msg())
        episode.publish(UInt32(data=EPISODE))
        reports.publish(_report(1, 1))
        assert spin_until(executor, lambda: calls == [1], 10.0)  # sampling history 1: blocked
        reports.publish(_report(2, 2))
        taken = spin_until(executor, lambda: histories and len(histories[-1].segments) == 3, 10.0)
        release.set()
        assert taken, "the report was not taken while the sampler ran"
        assert not samples or samples[-1].history_length != 1
        assert spin_until(executor, lambda: samples and samples[-1].history_length == 3, 30.0)
        assert all(s.history_length != 1 for s in samples)  # the overtaken result was dropped


def _prior_msg(problem: str = "sloper"):
    prior = problems.get(problem).prior
    return convert.shape_to_msg(prior, convert.Header(frame_id="dock_plane"))


def test_the_node_compiles_the_sampler_kernels_at_start_up(tmp_path, monkeypatch):
    """numba compiles the HMC loop's exit search and the descent's line scan on their first
    calls (~10 s after an install): the node pays it while starting, not in its first
    posterior after a contact."""
    calls = []
    for module in (inference_node.hmc_exit, inference_node.descent_scan):
        monkeypatch.setattr(module, "warm_up", lambda name=module.__name__: calls.append(name))
    with node_with_driver(launch_nodes("mock")["inference"], tmp_path):
        assert sorted(calls) == [
            "tactile_dock_ros.core.descent_scan",
            "tactile_dock_ros.core.hmc_exit",
        ]


def _samples_after_one_report(tmp_path, args, prior, history, check_node) -> ShapeSamples:
    """What the inference node (mock profile with ``args``; ``check_node`` sees it first)
    publishes once it has ``prior`` and one report of ``history`` (plan 1, contact failed)."""
    spec = launch_nodes("mock")["inference"]
    with node_with_driver(spec, tmp_path, args) as (node, driver, executor):
        check_node(node)
        samples = []
        driver.create_subscription(ShapeSamples, "shape_samples", samples.append, qos.LATCHED)
        priors = driver.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED)
        episode, reports = _inputs(driver)
        assert spin_until(executor, lambda: reports.get_subscription_count() > 0, 10.0)
        priors.publish(convert.shape_to_msg(prior, convert.Header(frame_id="dock_plane")))
        episode.publish(UInt32(data=EPISODE))
        report = Report(1, ExecutionReport.CONTACT_FAILED, history, history.b[-1], "", EPISODE)
        reports.publish(convert.report_to_msg(report, convert.Header(frame_id="dock_plane")))
        done = len(history)
        assert spin_until(executor, lambda: samples and samples[-1].history_length == done, 30.0)
    return samples[-1]


def test_the_node_publishes_samples_on_which_the_slides_could_happen(tmp_path):
    """A report of one compliant slide down a 35-degree slope whose edges may hold under the
    prior: about 72 % of the sampler's draws would contradict it (test_episode_posterior);
    the node publishes only samples on which it could have happened, under its
    ``load_direction``: about 56 of 100 after the top-up (49-62 over 10 seeds, one round
    22-34; test_episode_posterior)."""
    from test_episode_posterior import HISTORY, LOAD, MU, PRIOR

    def uses_the_load(node):
        np.testing.assert_array_equal(node.load, LOAD)

    args = ["-p", "inference:num_samples:=100"]
    msg = _samples_after_one_report(tmp_path, args, PRIOR, HISTORY, uses_the_load)
    vertices = convert.samples_from_msg(msg)
    assert 35 <= len(vertices) <= 100
    assert slides.consistent_with_slides(vertices, False, HISTORY, [1, 1], LOAD, MU).all()


@pytest.mark.parametrize("draws", [3000, 0])
def test_with_no_edge_holding_the_node_draws_on_to_give_up_draws(tmp_path, draws):
    """A 60-degree slope with 1.6 mm of noise per coordinate never holds the load (the friction
    angle is 26.6 degrees): after a contact the node draws on to ``give_up_draws`` and publishes
    them all, so the planner's give-up reads "no hold in 3000"; 0 turns that off."""
    from test_episode_posterior import LOAD, MU
    from test_slides import slide_probes, slope_shape

    from tactile_dock_ros.core import planner
    from tactile_dock_ros.core.shape import GaussianShape

    def has_the_parameter(node):
        assert node.p.give_up_draws == draws

    steep = slope_shape(8, 60.0)
    prior = GaussianShape(steep.ravel(), 0.0016 * np.eye(16), closed=False, friction=MU)
    args = ["-p", "inference:num_samples:=100", "-p", f"inference:give_up_draws:={draws}"]
    msg = _samples_after_one_report(
        tmp_path, args, prior, slide_probes(steep, [5]), has_the_parameter
    )
    vertices = convert.samples_from_msg(msg)
    wanted = max(draws, 100)  # a chain that verifies no draw is dropped: a few fewer at most
    assert 0.9 * wanted <= len(vertices) <= wanted and msg.num_samples == len(vertices)
    assert not planner.edge_holds_anywhere(vertices, prior, LOAD)


def test_a_sample_request_draws_on_once_for_the_history_it_names(tmp_path):
    """The planner's give-up check (``sample_request``): requests without the episode's nonce,
    of another history length or hold, or for no more samples than were published are refused
    (dropped, counted, no state changed); the planner's request gets the published samples
    followed by more draws of the same posterior (every one consistent with the slide), once
    per history."""
    from tactile_dock_ros.msg import EpisodeStatus, SampleRequest
    from test_episode_posterior import HISTORY, LOAD, MU, PRIOR

    nonce = 987654321
    spec = launch_nodes("mock")["inference"]
    with node_with_driver(spec, tmp_path, ["-p", "inference:num_samples:=100"]) as (
        node,
        driver,
        executor,
    ):
        samples = []
        driver.create_subscription(ShapeSamples, "shape_samples", samples.append, qos.LATCHED)
        priors = driver.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED)
        status = driver.create_publisher(EpisodeStatus, "episode_status", qos.LATCHED)
        requests = driver.create_publisher(SampleRequest, "sample_request", qos.EVENTS)
        episode, reports = _inputs(driver)
        inputs = (reports, status, requests)
        assert spin_until(executor, lambda: all(p.get_subscription_count() for p in inputs), 10.0)
        priors.publish(convert.shape_to_msg(PRIOR, convert.Header(frame_id="dock_plane")))
        status.publish(EpisodeStatus(episode=EPISODE, state=EpisodeStatus.RUNNING, nonce=nonce))
        episode.publish(UInt32(data=EPISODE))
        assert spin_until(  # every input in before the report: it alone changes the state
            executor,
            lambda: node.status_hold == (EPISODE, 0) and node.prior is not None
            and node.episode == EPISODE and not node.gate.authentic(EPISODE, nonce + 1),
            10.0,
        )  # fmt: skip
        report = Report(1, ExecutionReport.CONTACT_FAILED, HISTORY, HISTORY.b[-1], "", EPISODE,
                        nonce)  # fmt: skip
        reports.publish(convert.report_to_msg(report, convert.Header(frame_id="dock_plane")))
        assert spin_until(executor, lambda: samples and samples[-1].history_length == 2, 30.0)

        def settled():  # the node's latest set received (a prior or status may resample)
            latest = node.published
            return (
                latest is not None
                and latest[0] == node.generation
                and np.array_equal(convert.samples_from_msg(samples[-1]), latest[1].vertices)
            )

        assert spin_until(executor, settled, 30.0)
        first, published = convert.samples_from_msg(samples[-1]), len(samples)
        latest = node.published
        node.sample()  # a second wake-up of the sampler for the same state samples nothing
        assert node.published is latest

        def request(nonce=nonce, hold=0, rows=2, count=400):
            return convert.sample_request_to_msg(
                convert.Header(), EPISODE, nonce, hold, rows, count
            )

        refused = [request(nonce=nonce + 1), request(rows=1), request(hold=9),
                   request(count=len(first))]  # fmt: skip
        for n, msg in enumerate(refused, start=1):
            requests.publish(msg)
            assert spin_until(
                executor, lambda n=n: node.malformed.dropped["/sample_request"] == n, 10.0
            ), msg
        assert node.request is None and not node.answered and len(samples) == published
        requests.publish(request())
        assert spin_until(executor, lambda: len(samples) == published + 1, 30.0)
        answer = samples[-1]
        assert answer.history_length == 2 and answer.hold_id == 0
        more = convert.samples_from_msg(answer)
        assert len(first) < len(more) <= 400
        np.testing.assert_array_equal(more[: len(first)], first)
        assert slides.consistent_with_slides(more, False, HISTORY, [1, 1], LOAD, MU).all()
        requests.publish(request())  # the same history again: answered already
        assert spin_until(executor, lambda: node.malformed.dropped["/sample_request"] == 5, 10.0)
        assert len(samples) == published + 1
