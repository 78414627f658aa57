"""ControlThread: the executor's control loop on a thread of its own (no ROS)."""

import itertools
import os
import threading
import time

import pytest

from tactile_dock_ros.nodes.control_thread import ControlThread

PERIOD_S = 0.01


def _thread(tick, priority=0):
    events = {"priority": [], "fault": [], "done": threading.Event()}

    def on_fault(err):
        events["fault"].append(err)
        events["done"].set()

    control = ControlThread(tick, PERIOD_S, priority, events["priority"].append, on_fault)
    return control, events


def test_ticks_until_stopped_and_never_after():
    ticks = []
    started = threading.Event()

    def tick():
        ticks.append(threading.get_ident())
        if len(ticks) >= 5:
            started.set()

    control, events = _thread(tick)
    control.start()
    assert started.wait(5.0)
    control.stop()
    n = len(ticks)
    assert not control._thread.is_alive()
    time.sleep(5 * PERIOD_S)  # five more periods: no tick after stop() returned
    assert len(ticks) == n
    assert set(ticks) == {control._thread.ident} != {threading.get_ident()}
    assert events["fault"] == [] and events["priority"] == []  # priority 0: not touched


def test_an_exception_ends_the_loop_and_goes_to_on_fault():
    ticks = []

    def tick():
        ticks.append(1)
        if len(ticks) == 2:
            raise ValueError("bad tick")

    control, events = _thread(tick)
    control.start()
    assert events["done"].wait(5.0)
    control._thread.join(5.0)
    assert not control._thread.is_alive() and len(ticks) == 2
    assert isinstance(events["fault"][0], ValueError)


def test_a_refused_priority_is_reported_and_the_loop_runs(monkeypatch):
    def refuse(*args):
        raise PermissionError("no rtprio")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    ran = threading.Event()
    control, events = _thread(ran.set, priority=50)
    control.start()
    assert ran.wait(5.0)
    control.stop()
    (refused,) = events["priority"]
    assert isinstance(refused, OSError) and "no rtprio" in str(refused)


def test_a_late_tick_is_not_caught_up_with_a_burst():
    """After a tick that overran 20 periods, the next ticks keep (about) their period."""
    stamps = []
    done = threading.Event()

    def tick():
        stamps.append(time.monotonic())
        if len(stamps) == 2:
            time.sleep(20 * PERIOD_S)
        if len(stamps) == 6:
            done.set()

    control, _ = _thread(tick)
    control.start()
    assert done.wait(5.0)
    control.stop()
    # a catch-up burst would run ticks 3-6 back to back; the schedule restarts at tick 3 and
    # the loop never ticks early (scheduling may only stretch this)
    assert stamps[5] - stamps[2] >= 2.5 * PERIOD_S, stamps


@pytest.mark.parametrize("timeout_s", [0.0, 1.0])
def test_stop_from_the_control_thread_itself_does_not_deadlock(timeout_s):
    holder = {}
    done = threading.Event()

    def tick():
        holder["control"].stop(timeout_s)
        done.set()

    control, events = _thread(tick)
    holder["control"] = control
    control.start()
    assert done.wait(5.0)
    control._thread.join(5.0)
    assert not control._thread.is_alive() and events["fault"] == []


def test_a_watchdog_deadline_ticks_once_between_periods():
    """A deadline 1/10 into a long period gets one tick at it (not at the period's end), a
    deadline already answered none, and the periodic schedule goes on. The period is long so
    that a loaded machine's scheduling delay (tenths of a second) cannot blur the two."""
    period_s = 1.0
    stamps = []
    done = threading.Event()
    start = time.monotonic()
    deadlines = {"value": start + 0.1 * period_s}

    def tick():
        stamps.append(time.monotonic())
        if len(stamps) == 4:
            done.set()

    control = ControlThread(
        tick, period_s, 0, lambda err: None, lambda err: None, lambda: deadlines["value"]
    )
    control.start()
    assert done.wait(10.0)
    control.stop()
    offsets = [t - start for t in stamps]
    # the first period's tick comes at its end: the deadline's comes first, once
    assert 0.1 * period_s <= offsets[0] < 0.75 * period_s, offsets
    assert [round(t / period_s) for t in offsets[1:]] == [1, 2, 3], offsets


def test_a_deadline_that_moves_later_is_not_acted_on_early():
    """The stream came back: the deadline moved past the period, so no extra tick."""
    period_s = 0.2
    stamps = []
    done = threading.Event()

    def deadline():  # always half a period ahead of now: never reached
        return time.monotonic() + 0.5 * period_s

    def tick():
        stamps.append(time.monotonic())
        if len(stamps) == 3:
            done.set()

    control = ControlThread(tick, period_s, 0, lambda err: None, lambda err: None, deadline)
    control.start()
    assert done.wait(10.0)
    control.stop()
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    assert all(g >= 0.9 * period_s for g in gaps), gaps
