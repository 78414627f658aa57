"""Executor health, ROS-free: sensor stream ages and rates, episode admission of plans.

``StreamWatch`` keeps the arrival times of one stream (a sensor, or the control ticks) over a
sliding window: the age of the newest sample is what the executor's ``sensor_timeout`` tests,
the rate and the longest gap are what its diagnostics report. ``EpisodeGate`` decides from the
planner's ``episode_status`` whether a plan may run: a plan of an episode that is over never
moves the arm.
"""

from __future__ import annotations

from collections import deque
from enum import Enum

import numpy as np


class StreamWatch:
    """Arrival times (seconds, one clock) of a stream over the last ``window_s`` seconds."""

    def __init__(self, window_s: float = 1.0) -> None:
        if window_s <= 0:
            raise ValueError("window_s must be > 0")
        self.window_s = window_s
        self.last: float | None = None
        self.count = 0  # samples since start
        self._times: deque[float] = deque()

    def add(self, t: float) -> None:
        self.last = t
        self.count += 1
        self._times.append(t)
        while self._times[0] < t - self.window_s:
            self._times.popleft()

    def age(self, now: float) -> float:
        """Seconds since the newest sample; inf before the first."""
        return np.inf if self.last is None else now - self.last

    def rate(self, now: float) -> float:
        """Samples per second over the window ending at ``now``."""
        return sum(1 for t in self._times if t > now - self.window_s) / self.window_s

    def max_gap(self, now: float) -> float:
        """Longest interval between samples in the window, including the one still open at
        ``now``; inf before the first sample."""
        if self.last is None:
            return np.inf
        times = np.array([t for t in self._times if t > now - self.window_s] + [now])
        return float(np.diff(times).max()) if len(times) > 1 else now - self.last


class Admission(Enum):
    RUN = "run"
    WAIT = "wait"  # a newer episode whose RUNNING status has not arrived yet
    REFUSE = "refuse"


class EpisodeGate:
    """Admission of plans by their episode id, from the planner's ``episode_status``.

    Until the first status arrives (no planner on the graph, e.g. a test playing the planner)
    every plan runs. After that a plan runs only while its episode is the current one and
    RUNNING; a plan of an episode seen earlier, or of the current one once it ended, is
    refused; a plan of an unknown episode waits for its status (DDS does not order the plan
    and status topics): the executor drops that copy unseen, and the planner's next copy
    (resent every 0.5 s) runs once the RUNNING status came.

    Identity (``authentic``): the status carries the episode's nonce, a random number the
    planner mints at the start; plans and reports of an episode whose status gave a nonce
    count only with that nonce. Decision: a plan or report is matched to what the planner sent,
    not merely "newer": a stray node (a test tool, a bag replayed on the live graph, another
    robot's stack on the domain) that publishes a plan or report for the running episode does
    not know the nonce, and its message is dropped before it changes any state. It is not an
    authentication: a node that reads the status can copy it; SROS2 access control is that.
    """

    def __init__(self) -> None:
        self.current: int | None = None
        self.running = False
        self._seen: set[int] = set()
        self._nonces: dict[int, int] = {}  # episode -> its nonce (0: the planner gave none)

    def update(self, episode: int, state: str, nonce: int = 0) -> None:
        self._seen.add(episode)
        self._nonces[episode] = nonce
        self.current, self.running = episode, state == "RUNNING"

    def authentic(self, episode: int, nonce: int) -> bool:
        """False for a plan or report of ``episode`` whose status gave another nonce."""
        expected = self._nonces.get(episode, 0)
        return expected == 0 or nonce == expected

    def admit(self, episode: int) -> tuple[Admission, str]:
        """(decision, reason for a refusal or a wait)."""
        if self.current is None or (episode == self.current and self.running):
            return Admission.RUN, ""
        if episode == self.current:
            return Admission.REFUSE, f"episode {episode} is over"
        if episode in self._seen:
            return Admission.REFUSE, f"episode {episode} was superseded by {self.current}"
        return Admission.WAIT, f"no RUNNING status for episode {episode}"
