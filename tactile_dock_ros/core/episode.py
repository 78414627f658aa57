"""What the exploration cycle carries from one plan to the next (paper Sec. III-B), and the
planner's settings.

Each cycle infers the posterior given the history, plans on it and adds what the move felt.
``EpisodeState`` is everything the next cycle needs besides the prior: the history H with the
move that observed each row (the slides, ``core.slides``), the rows the sampler dropped as
inconsistent, the aim points of earlier plans (eq. 24's P'), the tool position and the previous
posterior (the sampler's warm start). It is immutable: each change returns a new state, so a
thread may plan or sample on a state while another records the next report. Its one owner per
loop is ``explore.run_episode``, the inference and planner nodes, and ``tools.replay``;
``nodes.convert`` maps it to and from ContactHistory.

``PlannerConfig`` holds the settings of ``planner.plan`` that do not change within an episode
(``explore`` varies the objective per cycle for the IG baseline). Friction is the prior's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .history import History
from .sampling import Deferral
from .simulate import MAX_SLIDE_M

OBJECTIVES = ("ours", "greedy", "window", "info_gain")  # planner.score


def _frozen(value, dtype, shape: tuple, name: str) -> np.ndarray:
    """A read-only finite copy of ``value`` of ``shape`` (-1: any length)."""
    array = np.array(value, dtype=dtype)
    try:
        array = array.reshape(shape)
    except ValueError:
        raise ValueError(f"{name} must have shape {shape} (-1: any), got {array.shape}") from None
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got {array.tolist()}")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class EpisodeState:
    """The exploration cycle's state between plans.

    Attributes:
        history: the observations so far (Sec. III-A3).
        move_ids: (k,) the move (plan id, from 1; 0 unknown) that observed each history row;
            default: all unknown.
        dropped: history rows the newest posterior ignored as inconsistent
            (``PosteriorSamples.dropped``; ``ShapeSamples.dropped_segments`` carries these and
            the deferred ones).
        deferral: the history rows the newest posterior left out while their seed search goes
            on, not judged yet (``sampling.Deferral``; the next sampling tries them again);
            None: none. ``deferred``: its rows; ``ignored``: dropped and deferred rows.
        targets: (p, 2) aim points of the earlier DOCK plans, metres (eq. 24's P').
        tool: (2,) current tool position in the plane, metres; None while unknown.
        warm_start: (N, m) the previous posterior in z (``sample_posterior(init_z=...)``);
            None: sample cold.
    """

    history: History = field(default_factory=History)
    move_ids: np.ndarray | None = None
    dropped: np.ndarray = ()
    targets: np.ndarray = ()
    tool: np.ndarray | None = None
    warm_start: np.ndarray | None = None
    deferral: Deferral | None = None

    def __post_init__(self) -> None:
        k = len(self.history)
        ids = np.zeros(k, int) if self.move_ids is None else self.move_ids
        values = {
            "move_ids": _frozen(ids, int, (-1,), "move_ids"),
            "dropped": _frozen(self.dropped, int, (-1,), "dropped rows"),
            "targets": _frozen(self.targets, float, (-1, 2), "targets"),
        }
        if len(values["move_ids"]) != k:
            raise ValueError(f"move_ids has {len(values['move_ids'])} entries for {k} rows")
        if np.any(values["move_ids"] < 0):
            raise ValueError(f"move ids must be >= 0, got {values['move_ids'].tolist()}")
        deferred = np.zeros(0, int) if self.deferral is None else self.deferral.rows
        for rows, name in ((values["dropped"], "dropped"), (deferred, "deferred")):
            if np.any((rows < 0) | (rows >= k)):
                raise ValueError(f"{name} rows {rows.tolist()} outside the {k}-row history")
        if self.tool is not None:
            values["tool"] = _frozen(self.tool, float, (2,), "tool position")
        if self.warm_start is not None:
            z = np.asarray(self.warm_start, float)
            values["warm_start"] = _frozen(z, float, (len(z), -1), "warm start") if len(z) else None
        for name, value in values.items():
            object.__setattr__(self, name, value)

    @property
    def deferred(self) -> np.ndarray:
        """History rows the newest posterior left out for now (``deferral.rows``)."""
        return np.zeros(0, int) if self.deferral is None else self.deferral.rows

    @property
    def ignored(self) -> np.ndarray:
        """History rows the newest posterior's samples need not satisfy: dropped and deferred
        ones (the planner's slide check and retreat leave them out), sorted."""
        return np.union1d(self.dropped, self.deferred).astype(int)

    def record(self, evidence: History, plan_id: int) -> EpisodeState:
        """The state with plan ``plan_id``'s evidence appended (plans record in order, ids from
        1). The dropped and deferred rows stay valid (they index the older rows) until the next
        sampling."""
        newest = int(self.move_ids.max(initial=0))
        if int(plan_id) != plan_id or plan_id < 1 or plan_id <= newest:
            raise ValueError(f"plan id {plan_id} must be >= 1 and above the newest, {newest}")
        return dataclasses.replace(
            self,
            history=self.history.extend(evidence.a, evidence.b, evidence.status),
            move_ids=np.concatenate([self.move_ids, np.full(len(evidence), int(plan_id))]),
        )

    def with_history(self, history: History, move_ids) -> EpisodeState:
        """The state with this whole history (a ContactHistory received); the dropped and
        deferred rows are cleared since they indexed the previous one."""
        return dataclasses.replace(
            self,
            history=history,
            move_ids=move_ids,
            dropped=(),
            deferral=None,
        )

    def sampled(
        self, z: np.ndarray | None = None, dropped=(), deferral: Deferral | None = None
    ) -> EpisodeState:
        """The state after sampling its posterior: ``z`` (N, m) the next warm start (None or
        no rows: none), ``dropped`` the history rows the sampler ignored as inconsistent,
        ``deferral`` those it left out for now (``PosteriorSamples.deferral``)."""
        return dataclasses.replace(self, warm_start=z, dropped=dropped, deferral=deferral)

    def aim(self, target) -> EpisodeState:
        """The state with a DOCK plan's aim point (2,) added to the targets (eq. 24)."""
        return dataclasses.replace(self, targets=np.vstack([self.targets, np.reshape(target, 2)]))

    def move(self, tool) -> EpisodeState:
        """The state with the tool at ``tool`` (2,) metres."""
        return dataclasses.replace(self, tool=tool)


@dataclass(frozen=True)
class PlannerConfig:
    """Settings of ``planner.plan`` (Sec. V-B), checked at construction.

    Attributes:
        load: unit push direction of the loading move in the plane (the paper's -f_load);
            any finite nonzero 2-vector, normalized here.
        contact_resolution: w of eq. (24), metres > 0; also the planner's step (w / 2) and
            likely-obstacle-region margin.
        give_up_threshold: give up when the best docking probability is below it, in [0, 1).
        objective: one of ``OBJECTIVES`` (``planner.score``).
        compliant: motion model of the probabilistic simulation (Sec. V-A). Non-compliant:
            a move docks only where its first contact sticks, also when the executor slides
            on after a slip (``slide_on_slip``, ``simulate.guarded_path``: evidence only), so
            the prediction needs no setting of its own.
        max_path_attempts: at most this many candidate sites are path-planned, >= 1.
        workspace: ``((x_min, y_min), (x_max, y_max))`` in the plane, metres: the executor's
            box (its ``workspace_min/max``). A path with a waypoint outside is not planned (the
            executor would refuse the plan and end the episode ABORTED); None: no box.
        max_slide: the executor's ``max_slide``, metres >= 0: how far a slide it reports only
            by its first contact can carry the tool from its recorded moves (``planner.retrace``
            reaches this plus ``planner.RETRACE_MARGIN``).
    """

    load: tuple[float, float] = (0.0, -1.0)
    contact_resolution: float = 0.01
    give_up_threshold: float = 1e-3
    objective: str = "ours"
    compliant: bool = True
    max_path_attempts: int = 20
    workspace: tuple[tuple[float, float], tuple[float, float]] | None = None
    max_slide: float = MAX_SLIDE_M

    def __post_init__(self) -> None:
        load = np.asarray(self.load, float).reshape(-1)
        if load.shape != (2,) or not np.all(np.isfinite(load)) or np.linalg.norm(load) < 1e-12:
            raise ValueError(f"load must be a finite nonzero 2-vector, got {self.load}")
        load = load / np.linalg.norm(load)
        object.__setattr__(self, "load", (float(load[0]), float(load[1])))
        if not (np.isfinite(self.contact_resolution) and self.contact_resolution > 0):
            raise ValueError(
                f"contact_resolution must be > 0 metres, got {self.contact_resolution}"
            )
        if not (0 <= self.give_up_threshold < 1):
            raise ValueError(f"give_up_threshold must be in [0, 1), got {self.give_up_threshold}")
        if self.objective not in OBJECTIVES:
            raise ValueError(f"unknown objective {self.objective!r}; choose from {OBJECTIVES}")
        if not isinstance(self.compliant, bool | np.bool_):
            raise ValueError(f"compliant must be a bool, got {self.compliant!r}")
        attempts = self.max_path_attempts
        if isinstance(attempts, bool) or not isinstance(attempts, int | np.integer) or attempts < 1:
            raise ValueError(f"max_path_attempts must be >= 1, got {self.max_path_attempts}")
        if not (isinstance(self.max_slide, int | float) and 0 <= self.max_slide < np.inf):
            raise ValueError(f"max_slide must be finite and >= 0 metres, got {self.max_slide!r}")
        if self.workspace is not None:
            try:
                box = np.asarray(self.workspace, float)
            except (TypeError, ValueError):
                box = np.zeros(0)
            if box.shape != (2, 2) or not np.all(np.isfinite(box)) or np.any(box[0] >= box[1]):
                raise ValueError(
                    f"workspace must be finite (min, max) corners, got {self.workspace}"
                )
            object.__setattr__(self, "workspace", tuple(map(tuple, box.tolist())))

    def inside(self, points: np.ndarray) -> bool:
        """Whether every point (K, 2) lies in ``workspace`` (borders included; True without)."""
        if self.workspace is None:
            return True
        lo, hi = np.asarray(self.workspace)
        return bool(np.all((points >= lo) & (points <= hi)))
