"""Captured holds and their first-look evaluation, without moving the arm.

A climbing planner ranks candidate holds before it commits a limb: for each captured prior
(a *hold*) it asks what the docking planner would do on the episode's first cycle, the best
site and its P_dock (paper Sec. V-B, eq. 24 with no earlier aim, so J = P_dock). The first
cycle has an empty history, so its posterior samples are the prior's (Sec. III-B: x = A z + mu,
z ~ N(0, I)); ``evaluate_hold`` draws them through ``sampling.sample_posterior`` exactly as the
inference node does with no contact yet, from a generator seeded per call, then calls
``planner.plan`` from the tool position with the planner's ``PlannerConfig``. The same prior,
tool, settings and seed give the same answer.

``HoldStore`` keeps the captured holds (id, stamp, prior), bounded: the oldest is dropped.
Perception numbers them; the planner and inference keep the priors they receive on
``terrain_prior`` in a ``HoldStore`` of their own under perception's numbers (``add`` with
``hold_id``), so that a dock goal names a hold the way ``/evaluate_hold`` does.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from . import planner, sampling
from .episode import EpisodeState, PlannerConfig
from .history import History
from .shape import GaussianShape


@dataclass(frozen=True)
class Hold:
    """One captured prior: ``hold_id`` (from 1, increasing; 0: a prior that is no captured
    hold, ``ReceivedPriors.latest``), ``stamp`` (when it was captured,
    integer nanoseconds of the caller's clock) and the ``prior``."""

    hold_id: int
    stamp: int
    prior: GaussianShape


class HoldStore:
    """The latest ``capacity`` holds, oldest first; ids are unique and increase from 1."""

    def __init__(self, capacity: int) -> None:
        if isinstance(capacity, bool) or int(capacity) != capacity or capacity < 1:
            raise ValueError(f"capacity must be an integer >= 1, got {capacity!r}")
        self.capacity = int(capacity)
        self._holds: OrderedDict[int, Hold] = OrderedDict()
        self._last_id = 0

    def add(
        self, stamp: int, prior: GaussianShape, hold_id: int | None = None
    ) -> tuple[Hold, Hold | None]:
        """Store ``prior`` as a new hold captured at ``stamp`` (ns); returns it and the hold
        dropped to make room (or None). ``hold_id``: the id its source (perception) gave it,
        default the next one. Decision: the last id again replaces that hold (a latched message
        delivered again); an id below the last one means the source restarted its numbering, so
        the kept holds (of the old numbering) are forgotten first. A bad argument raises
        ValueError and stores nothing."""
        if not isinstance(prior, GaussianShape):
            raise ValueError(f"a hold's prior must be a GaussianShape, got {type(prior).__name__}")
        if isinstance(stamp, bool) or not isinstance(stamp, int | np.integer):
            raise ValueError(f"stamp must be integer nanoseconds, got {stamp!r}")
        if hold_id is None:
            hold_id = self._last_id + 1
        elif isinstance(hold_id, bool) or int(hold_id) != hold_id or hold_id < 1:
            raise ValueError(f"hold_id must be an integer >= 1, got {hold_id!r}")
        if hold_id < self._last_id:
            self._holds.clear()
        self._holds.pop(hold_id, None)
        self._last_id = int(hold_id)
        hold = Hold(self._last_id, int(stamp), prior)
        dropped = self._holds.popitem(last=False)[1] if len(self._holds) >= self.capacity else None
        self._holds[hold.hold_id] = hold
        return hold, dropped

    @property
    def next_id(self) -> int:
        """The id the next ``add`` gives."""
        return self._last_id + 1

    def get(self, hold_id: int) -> Hold | None:
        return self._holds.get(hold_id)

    def ids(self) -> list[int]:
        """The stored hold ids, oldest first."""
        return list(self._holds)

    def __len__(self) -> int:
        return len(self._holds)


class ReceivedPriors:
    """The priors a node received on ``terrain_prior``: the latest one (``Hold`` with its
    message's ``hold_id``, 0 when it is no captured hold) and the captured ones by id, the last
    ``capacity`` (a ``HoldStore`` under perception's numbers)."""

    def __init__(self, capacity: int) -> None:
        self.holds = HoldStore(capacity)
        self.latest: Hold | None = None

    def receive(self, hold_id: int, stamp: int, prior: GaussianShape) -> list[str]:
        """Keep a received prior; returns what to log (holds forgotten or dropped)."""
        notes = []
        if hold_id:
            last = self.holds.next_id - 1
            if hold_id < last:
                notes.append(f"hold {hold_id} after hold {last}: perception restarted, the earlier"
                             " holds are forgotten")  # fmt: skip
            hold, dropped = self.holds.add(stamp, prior, hold_id)
            if dropped is not None:
                notes.append(f"hold {dropped.hold_id} dropped: {self.holds.capacity} are kept")
        else:
            hold = Hold(0, int(stamp), prior)
        self.latest = hold
        return notes

    def resolve(self, hold_id: int) -> Hold | None:
        """The hold a dock goal (or episode) names: 0 the latest prior, else that kept hold;
        None when there is none."""
        return self.latest if hold_id == 0 else self.holds.get(hold_id)


@dataclass(frozen=True)
class HoldEvaluation:
    """What the first cycle's plan says about a hold.

    Attributes:
        decision: "dock" | "give_up" (``planner.Plan.decision``).
        site: (2,) the best site, metres: the plan's target point (an expected edge midpoint);
            on a give-up the candidate with the highest P_dock, NaN when there is none.
        site_p_dock: the loading move's P_dock at ``site`` (``planner.Candidates.p_dock``,
            capped), 0 when there is no site.
        path_p_dock: the whole path's P_dock (``planner.whole_path_p_dock``), 0 on a give-up.
        target_edge: the site's edge index, -1 when there is none.
        reason: the planner's reason text.
        seconds: wall time of sampling and planning.
    """

    decision: str
    site: np.ndarray
    site_p_dock: float
    path_p_dock: float
    target_edge: int
    reason: str
    seconds: float


def evaluate_hold(
    prior: GaussianShape,
    tool,
    config: PlannerConfig,
    n_samples: int = 100,
    seed: int = 0,
    method: str = "hmc",
) -> HoldEvaluation:
    """The first cycle's plan on ``prior`` from ``tool`` (2,) metres in the plane.

    ``n_samples`` prior draws from ``np.random.default_rng(seed)`` via
    ``sampling.sample_posterior`` with an empty history (the inference node's first cycle,
    ``method`` its sampler), then ``planner.plan``. Raises ValueError on malformed input (a
    tool position that is not a finite 2-vector, fewer than 2 samples, a bad method).
    """
    if not isinstance(prior, GaussianShape):
        raise ValueError(f"prior must be a GaussianShape, got {type(prior).__name__}")
    if not isinstance(config, PlannerConfig):
        raise ValueError(f"config must be a PlannerConfig, got {type(config).__name__}")
    if isinstance(n_samples, bool) or int(n_samples) != n_samples or n_samples < 2:
        raise ValueError(f"n_samples must be an integer >= 2 (a moment fit), got {n_samples}")
    started = time.perf_counter()
    state = EpisodeState(tool=tool)  # checks the tool position
    rng = np.random.default_rng(seed)
    samples = sampling.sample_posterior(prior, History(), int(n_samples), rng, method).vertices
    plan = planner.plan(samples, prior, state, config)
    site, site_p_dock, edge = np.full(2, np.nan), 0.0, -1
    candidates = plan.candidates
    if plan.decision == "dock":
        j = int(np.flatnonzero(candidates.edges == plan.target_edge)[0])
    elif candidates is not None and len(candidates.edges):
        j = int(np.argmax(candidates.p_dock))
    else:
        j = None
    if j is not None:
        site, site_p_dock = candidates.aim[j].copy(), float(candidates.p_dock[j])
        edge = int(candidates.edges[j])
    return HoldEvaluation(
        plan.decision,
        site,
        site_p_dock,
        float(plan.p_dock),
        edge,
        plan.reason,
        time.perf_counter() - started,
    )
