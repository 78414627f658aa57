"""Guarded-move execution of a docking plan as a control-rate state machine (ROS-free).

The executor node feeds :meth:`GuardedRun.step` with the tool position and the filtered,
bias-free contact force in the docking plane; it returns the Cartesian velocity to command.
Paper Sec. III-A2/3: each waypoint segment is a guarded move that stops when the contact force
exceeds the plan's threshold; the last segment is the loading move, along f_load, where the
stick/slip test decides docking.

Decisions where the paper leaves the robot side open:

* Stick/slip test: after contact on the loading move the tool keeps pushing along the load at
  the plan speed until the force reaches ``load_force``. If the tool moved less than
  ``slip_tolerance`` from the contact point it sticks (DOCKED, the tool holds there); otherwise
  it slipped, left (CCW from the motion) or right (CW) by the sign of the cross product of the
  motion and the displacement. A slip ends the attempt when the plan is non-compliant (unless
  ``slide_on_slip``, below).
* Compliant plans (``plan.compliant``, Sec. III-A2 and the compliant model of V-A) need an arm
  that is compliant across its motion (hardware or impedance control; the mock's
  ``lateral_stiffness``): after a slip the tool keeps pushing along the load and slides. It is
  stuck (DOCKED where it stopped, e.g. trapped at a vertex) once it holds still within
  ``slip_tolerance`` for ``settle_time`` under ``load_force`` (the push pauses at that force, so
  it never grows towards the limit); the attempt fails when the tool moves straight along the
  load for ``contact_resolution`` with less than the plan's contact force resisting the load
  (free space or a wall along the load: the surface turned away, the separation of
  ``core.simulate``) or the slide exceeds ``max_slide``.
  The evidence is that of ``core.explore``'s simulated robot: the status of the first contact (the
  slip), even when the slide then sticks, and after a slide that ended in separation slip
  observations every ``evidence_spacing`` of each edge the trace crossed completely toward the
  slip's side (``crossed_pieces``, ``core.slides.crossed_piece_evidence``). A finite lateral
  stiffness pulls back as the tool slides (a 25 N/m arm 10 cm off its line: 2.5 N), so long slides
  may stop on a slope that the paper's ideal compliance would slide down; the test reports the
  hold the arm actually has.
* Non-compliant plans with ``slide_on_slip`` (the executor's parameter; config/mock.yaml sets
  it): after the slip the tool keeps the load and slides as under a compliant plan, within
  ``max_slide`` and the force limits, only for the evidence: a slide that separates reports
  the same slip observations along the face (``core.simulate.guarded_path``'s
  ``slide_on_slip``, the simulated robot's rule). Decision: the attempt fails even when the
  slide then sticks (a vertex trap, or the arm's lateral spring holding it on a slope): a
  non-compliant plan docks only where its first contact sticks, which is the event the
  planner's non-compliant P_dock predicts; docking in a trap would make its predictions
  dishonest, and a stop it cannot tell from the spring's would give false evidence. Such a
  slide, like one cut at ``max_slide``, reports only the first contact. Measured on the
  held-out depth-prior truths (bench docking, non-compliant): clearly infeasible truths ended
  by the planner's give-up 31/48 instead of 10/48, attempts after a failure predicted 0.225
  for 0.140 docked instead of 0.221 for 0.119, feasible episodes docked 422/424 instead of
  419/424.
* Evidence, like ``core.simulate.guarded_path``: a FREE segment for the travelled part of each
  move, backed off by the contact resolution w from the contact point c, and a contact segment
  c - w/2 d -> c + w/2 d (d the move direction) with status COLLIDE (a prefix move hit
  something) or STICK / SLIP_LEFT / SLIP_RIGHT (the loading move).
* After any contact that did not dock the tool retreats ``retreat_distance`` against the move
  direction, so the next plan starts in free space and the F/T bias can be re-estimated. The
  retreat is guarded too: a force above the contact threshold against it ends it early.
  A tool still pressed against a surface after the retreat (more than ``released_fraction`` of
  the contact threshold) then moves along the measured force until it is released
  (``_step_release``).
  Before, a laterally compliant arm that had slid sideways could back into another face
  unguarded: the mock's node suite drove a retreat at 0.2 m/s into a notch face up to the 40 N
  limit (ABORTED) in 1-2 of 15 episodes per run.
* Safety, checked before every command: sensor age, tool inside the workspace box, force below
  the limit, command speed below the limit, the next position (tool + v dt) inside the box, and
  a time budget per plan. Any violation stops the run with ABORTED and the reason.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from tactile_dock_ros.core import simulate, slides
from tactile_dock_ros.core.geometry2d import cross, perp
from tactile_dock_ros.core.history import History, Status
from tactile_dock_ros.execution.types import Outcome, PlanCommand


@dataclass(frozen=True)
class Limits:
    """Hard limits of the arm in the docking plane: box (2,) metres, speed m/s, force N, s."""

    workspace_min: np.ndarray
    workspace_max: np.ndarray
    max_speed: float
    max_force: float
    sensor_timeout: float

    def inside(self, p: np.ndarray) -> bool:
        return bool(np.all(p >= self.workspace_min) and np.all(p <= self.workspace_max))


@dataclass(frozen=True)
class Settings:
    """Execution tuning: metres, newtons, seconds, 1/s."""

    contact_resolution: float = 0.01
    waypoint_tolerance: float = 0.002
    slip_tolerance: float = 0.002
    load_force: float = 12.0
    load_speed: float = 0.02  # pushing speed of the stick/slip test
    retreat_distance: float = 0.02
    approach_gain: float = 4.0  # speed = min(max_speed, gain * remaining distance)
    time_margin: float = 5.0  # time budget = 3 * ideal move time (``move_seconds``) + margin
    settle_time: float = 0.3  # a compliant slide is stuck after holding still this long
    max_slide: float = simulate.MAX_SLIDE_M  # a slide longer than this fails
    evidence_spacing: float = slides.EVIDENCE_SPACING_M  # one slip observation per this much slide
    slide_on_slip: bool = False  # non-compliant plans: slide after a slip, for evidence only
    released_fraction: float = 0.25  # below this fraction of the contact threshold: free


def move_seconds(path: np.ndarray, speed: float, settings: Settings) -> float:
    """Seconds the move controller ideally needs along ``path`` (n, 2): it approaches each
    waypoint at min(speed, approach_gain * remaining) until within waypoint_tolerance, so a
    segment of length d takes (d - k) / speed at full speed plus ln(min(d, k) / tolerance) /
    approach_gain of exponential approach, k = speed / approach_gain (ln 25 / 4 = 0.8 s per
    waypoint at 0.2 m/s). Decision: the plan's time budget is 3x this plus ``time_margin``;
    before, 3 x length / speed, which a plan of 42 short waypoints (node suite, sloper seed 2,
    8.5 s budget) overran and ABORTED."""
    d = np.linalg.norm(np.diff(np.asarray(path, float), axis=0), axis=1)
    knee = speed / settings.approach_gain
    cruise = np.maximum(d - knee, 0.0) / speed
    approach = np.log(np.maximum(np.minimum(d, knee) / settings.waypoint_tolerance, 1.0))
    return float(np.sum(cruise + approach / settings.approach_gain))


class _Phase(Enum):
    MOVE = "move"
    LOAD_TEST = "load test"
    SLIDE = "slide"
    RETREAT = "retreat"
    RELEASE = "release"
    DONE = "done"


def refusal(plan: PlanCommand, tool: np.ndarray, limits: Limits, settings: Settings) -> str:
    """Why the plan must not run ('' when it may): limits are checked before moving. A plan
    faster than the limit is refused rather than slowed down: its contact threshold was chosen
    for its speed."""
    numbers = np.concatenate([np.ravel(plan.waypoints), [plan.max_speed, plan.force_threshold]])
    if not np.all(np.isfinite(numbers)) or not np.all(np.isfinite(tool)):
        return "NaN or inf in the plan or the tool position"
    if plan.max_speed <= 0 or plan.force_threshold <= 0:
        return "plan speed and contact threshold must be > 0"
    if plan.max_speed > limits.max_speed:
        return f"plan speed {plan.max_speed:.3f} m/s exceeds the limit {limits.max_speed} m/s"
    if max(plan.force_threshold, settings.load_force) > limits.max_force:
        return (
            f"contact threshold {plan.force_threshold:.1f} N / load force "
            f"{settings.load_force:.1f} N exceed the force limit {limits.max_force} N"
        )
    if plan.force_threshold >= settings.load_force:
        return f"contact threshold {plan.force_threshold:.1f} N must be below the load force"
    outside = [i for i, w in enumerate(plan.waypoints) if not limits.inside(w)]
    if outside:
        return f"waypoints {outside} lie outside the workspace box"
    if not limits.inside(tool):
        return f"tool at {np.round(tool, 3).tolist()} is outside the workspace box"
    return ""


@dataclass
class GuardedRun:
    """One plan's execution. Call :meth:`step` at the control rate until ``done``."""

    plan: PlanCommand
    tool: np.ndarray  # (2,) where the run starts
    limits: Limits
    settings: Settings
    t_start: float  # seconds
    outcome: Outcome | None = None
    detail: str = ""
    stop_point: np.ndarray | None = None
    max_speed_commanded: float = 0.0
    _phase: _Phase = _Phase.MOVE
    _path: np.ndarray = field(init=False)
    _move: int = 0
    _move_start: np.ndarray = field(init=False)
    _anchor: np.ndarray | None = None
    _segments: list = field(default_factory=list)
    _budget: float = field(init=False)
    _t: float = 0.0  # time of the current tick, seconds
    _force: np.ndarray = field(default_factory=lambda: np.zeros(2))  # of this tick, newtons
    _slip: Status | None = None  # first-contact status of a compliant slide
    _still: tuple = ()  # (position, since seconds): where a compliant slide last rested
    _trace: list = field(default_factory=list)  # tool positions on the surface while sliding
    _release_until: float = 0.0  # seconds: when a release that makes no way ends
    _release_limit: float = 0.0  # newtons: a release that meets more force than this ends

    def __post_init__(self) -> None:
        tool = np.asarray(self.tool, float)
        if reason := refusal(self.plan, tool, self.limits, self.settings):
            self._finish(Outcome.ABORTED, f"refused: {reason}", tool)
            return
        waypoints = self.plan.waypoints
        far = np.linalg.norm(waypoints[0] - tool) > self.settings.waypoint_tolerance
        self._path = np.vstack([tool, waypoints]) if far else np.vstack([tool, waypoints[1:]])
        self._move_start = tool
        self._speed = min(self.plan.max_speed, self.limits.max_speed)
        ideal = move_seconds(self._path, self._speed, self.settings)
        self._budget = 3.0 * ideal + self.settings.time_margin
        if self._slides:  # room for a slide at the loading speed, and for settling
            slide = self.settings.max_slide / min(self.settings.load_speed, self._speed)
            self._budget += slide + self.settings.settle_time

    @property
    def _slides(self) -> bool:
        """Whether a slip under the load goes on as a slide (docking only if compliant)."""
        return bool(self.plan.compliant or self.settings.slide_on_slip)

    @property
    def done(self) -> bool:
        return self._phase is _Phase.DONE

    @property
    def history(self) -> History:
        """The evidence gathered so far, in execution order."""
        if not self._segments:
            return History()
        a, b, s = zip(*self._segments, strict=True)
        return History(np.array(a), np.array(b), np.array(s))

    def abort(self, reason: str, tool: np.ndarray) -> np.ndarray:
        self._finish(Outcome.ABORTED, reason, tool)
        return np.zeros(2)

    def step(
        self,
        t: float,
        tool: np.ndarray,
        force: np.ndarray,
        sensor_age: float,
        normal_force: float = 0.0,
    ) -> np.ndarray:
        """Velocity command (2,) m/s for this control tick; zero once done. ``force`` (2,) is
        the in-plane contact force, ``normal_force`` its component along the plane normal (N):
        the force limit applies to the whole 3-D force."""
        if self.done:
            return np.zeros(2)
        tool = np.asarray(tool, float)
        magnitude = float(np.linalg.norm(force))
        if sensor_age > self.limits.sensor_timeout:
            return self.abort(f"sensor timeout: data {sensor_age:.2f} s old", tool)
        if not self.limits.inside(tool):
            return self.abort(f"tool left the workspace at {np.round(tool, 3).tolist()}", tool)
        total = float(np.hypot(magnitude, normal_force))
        if total > self.limits.max_force:
            return self.abort(f"force {total:.1f} N (3-D) above the limit", tool)
        if t - self.t_start > self._budget:
            return self.abort(f"{self._phase.value} exceeded the {self._budget:.1f} s budget", tool)
        self._t, self._force = t, np.asarray(force, float)
        velocity = {
            _Phase.MOVE: self._step_move,
            _Phase.LOAD_TEST: self._step_load_test,
            _Phase.SLIDE: self._step_slide,
            _Phase.RETREAT: self._step_retreat,
            _Phase.RELEASE: self._step_release,
        }[self._phase](tool, magnitude)
        speed = float(np.linalg.norm(velocity))
        if speed > self._speed * (1 + 1e-9):
            velocity *= self._speed / speed
        return velocity

    def check_next(self, tool: np.ndarray, velocity: np.ndarray, dt: float) -> np.ndarray:
        """The command to send: ``velocity`` unless it would leave the box within ``dt``."""
        if not self.done and not self.limits.inside(tool + velocity * dt):
            return self.abort("the next command would leave the workspace box", tool)
        self.max_speed_commanded = max(self.max_speed_commanded, float(np.linalg.norm(velocity)))
        return velocity

    # ------------------------------------------------------------------ phases

    def _direction(self) -> np.ndarray:
        d = self._path[self._move + 1] - self._path[self._move]
        return d / max(np.linalg.norm(d), 1e-12)

    def _loading(self) -> bool:
        return self._move == len(self._path) - 2

    def _step_move(self, tool: np.ndarray, force: float) -> np.ndarray:
        d = self._direction()
        if force > self.plan.force_threshold:
            self._record_free(tool, d)
            if self._loading():
                self._anchor = tool.copy()
                self._phase = _Phase.LOAD_TEST
                return self._step_load_test(tool, force)
            self._record_contact(tool, d, Status.COLLIDE)
            return self._start_retreat(tool, f"collided on move {self._move + 1}")
        target = self._path[self._move + 1]
        remaining = float((target - tool) @ d)
        if remaining <= self.settings.waypoint_tolerance:
            if self._loading():
                self._segments.append((self._move_start, tool.copy(), Status.FREE))
                self._finish(Outcome.NO_CONTACT, "the loading move ended without contact", tool)
                return np.zeros(2)
            self._segments.append((self._move_start, tool.copy(), Status.FREE))
            self._move += 1
            self._move_start = tool.copy()
            return self._step_move(tool, force)
        to_target = target - tool
        speed = min(self._speed, self.settings.approach_gain * remaining)
        return to_target / max(np.linalg.norm(to_target), 1e-12) * speed

    def _step_load_test(self, tool: np.ndarray, force: float) -> np.ndarray:
        d = self._direction()
        moved = tool - self._anchor
        if np.linalg.norm(moved) > self.settings.slip_tolerance:
            status = Status.SLIP_LEFT if cross(d, moved) > 0 else Status.SLIP_RIGHT
            if self._slides:
                self._phase, self._slip, self._still = _Phase.SLIDE, status, (tool.copy(), self._t)
                return self._step_slide(tool, force)
            self._record_contact(self._anchor, d, status)
            return self._start_retreat(tool, f"slipped {status.name.lower()} under the load")
        if force >= self.settings.load_force:
            self._record_contact(self._anchor, d, Status.STICK)
            self._finish(Outcome.DOCKED, f"stuck under {force:.1f} N", tool)
            return np.zeros(2)
        return d * min(self.settings.load_speed, self._speed)

    def _step_slide(self, tool: np.ndarray, force: float) -> np.ndarray:
        d = self._direction()
        slid = float(np.linalg.norm(tool - self._anchor))
        how = f"slid {slid:.3f} m {self._slip.name.lower().replace('slip_', '')}"
        rest, since = self._still
        moved = tool - rest
        across = abs(cross(d, moved))
        # Moving straight along the load, little of the force resisting it: free space, or a
        # surface parallel to the load (a wall the arm's lateral spring presses against).
        free = (
            across <= self.settings.slip_tolerance
            and moved @ d >= self.settings.contact_resolution
            and -(self._force @ d) < self.plan.force_threshold
        )
        if free or slid > self.settings.max_slide:
            self._record_contact(self._anchor, d, self._slip)
            if free:  # the trace up to the rest point ended at the vertex it slid off
                trace = np.array([self._anchor, *self._trace, rest])
                left = perp(d)  # the side a SLIP_LEFT slide moves to
                side = left if self._slip == Status.SLIP_LEFT else -left
                w = self.settings.contact_resolution
                pieces = crossed_pieces(trace, w, side)
                evidence = slides.crossed_piece_evidence(
                    *pieces, d, w, self._slip, self.settings.evidence_spacing
                )
                self._segments += zip(evidence.a, evidence.b, evidence.status, strict=True)
            why = "lost contact" if free else "exceeded max_slide"
            return self._start_retreat(tool, f"{how} and {why} under the load")
        if across > self.settings.slip_tolerance or moved @ d < -self.settings.slip_tolerance:
            self._still = (tool.copy(), self._t)  # still sliding along the surface
            self._trace.append(tool.copy())
        elif np.linalg.norm(moved) <= self.settings.slip_tolerance:
            if force >= self.settings.load_force and self._t - since >= self.settings.settle_time:
                self._record_contact(self._anchor, d, self._slip)
                if not self.plan.compliant:  # slide_on_slip: evidence only, never a dock
                    why = f"{how}, then stuck under {force:.1f} N: not a dock (non-compliant)"
                    return self._start_retreat(tool, why)
                self._finish(Outcome.DOCKED, f"{how}, then stuck under {force:.1f} N", tool)
                return np.zeros(2)
        if force >= self.settings.load_force:
            return np.zeros(2)  # hold the load: friction either holds or the slide resumes
        return d * min(self.settings.load_speed, self._speed)

    def _start_retreat(self, tool: np.ndarray, why: str) -> np.ndarray:
        self._phase = _Phase.RETREAT
        self._anchor = tool.copy()
        self.detail = why
        return self._step_retreat(tool, float(np.linalg.norm(self._force)))

    def _step_retreat(self, tool: np.ndarray, force: float) -> np.ndarray:
        """Back off ``retreat_distance`` against the move, guarded like a move: a force above
        the plan's contact threshold resisting the retreat (the way back is blocked: the tool
        slid or was pulled sideways since it came) ends it where it is. Either way the contact
        is then released if the tool still feels it (``_step_release``)."""
        d = self._direction()
        moved = (self._anchor - tool) @ d
        if moved >= self.settings.retreat_distance:
            return self._start_release(tool, force, "")
        if self._force @ d > self.plan.force_threshold:  # resists motion along -d
            return self._start_release(
                tool, force, f"; retreat blocked after {max(moved, 0.0):.3f} m"
            )
        return -d * self._speed

    def _start_release(self, tool: np.ndarray, force: float, note: str) -> np.ndarray:
        """After the retreat: done if the tool is free, else release the contact."""
        self.detail += note
        if force <= self.settings.released_fraction * self.plan.force_threshold:
            self._finish(Outcome.CONTACT_FAILED, self.detail, tool)
            return np.zeros(2)
        self._phase, self._anchor = _Phase.RELEASE, tool.copy()
        self._release_limit = max(force, self.plan.force_threshold)
        release_time = self.settings.retreat_distance / min(self.settings.load_speed, self._speed)
        self._release_until = self._t + release_time + 1.0
        self._budget = max(self._budget, self._release_until - self.t_start + 1.0)
        return self._step_release(tool, force)

    def _step_release(self, tool: np.ndarray, force: float) -> np.ndarray:
        """Move along the contact force (away from what pushes the tool) at the loading speed
        until it falls to ``released_fraction`` of the plan's contact threshold, for at most
        ``retreat_distance`` or the time that takes plus 1 s (a jammed tool does not move; the
        plan's time budget grows to cover it). It is guarded: a force growing above the larger of
        its start value and the contact threshold (the reading does not point out of the
        surface: a second face, or a bias error) ends it ("grew to ... N").

        Decision: an arm that is soft across its motion can end the retreat still pressed
        against a face (it slid sideways on contact, or the way back was blocked). The node
        suite's notch episodes then started the next plan in contact: its F/T bias, taken at
        the plan start, absorbed 1.4-3.9 N, the first move "collided" at once, its retreat was
        blocked at 0.000 m, and the planner gave up with the tool in the likely-obstacle region.
        The measured force points out of the surface (within the friction cone of its normal),
        so moving along it separates the tool; the release is not recorded as evidence. What
        it leaves (at most a quarter of the threshold, 0.75 N at the mock's 3 N) is the next
        plan's bias error; half the threshold left 0.8 N in a bias in the node suite.
        """
        moved = float(np.linalg.norm(tool - self._anchor))
        if force <= self.settings.released_fraction * self.plan.force_threshold:
            self._finish(
                Outcome.CONTACT_FAILED, f"{self.detail}; released after {moved:.3f} m", tool
            )
            return np.zeros(2)
        grew = force > self._release_limit
        if grew or moved >= self.settings.retreat_distance or self._t >= self._release_until:
            how = "grew to" if grew else "still"
            why = f"{self.detail}; {how} {force:.1f} N in contact after {moved:.3f} m of release"
            self._finish(Outcome.CONTACT_FAILED, why, tool)
            return np.zeros(2)
        return self._force / force * min(self.settings.load_speed, self._speed)

    # ------------------------------------------------------------------ evidence

    def _record_free(self, contact: np.ndarray, d: np.ndarray) -> None:
        end = contact - self.settings.contact_resolution * d
        if (end - self._move_start) @ d > 0:
            self._segments.append((self._move_start, end, Status.FREE))

    def _record_contact(self, contact: np.ndarray, d: np.ndarray, status: Status) -> None:
        half = 0.5 * self.settings.contact_resolution * d
        self._segments.append((contact - half, contact + half, status))

    def _finish(self, outcome: Outcome, detail: str, tool: np.ndarray) -> None:
        self.outcome, self.detail = outcome, detail
        self.stop_point = np.asarray(tool, float).copy()
        self._phase = _Phase.DONE


def crossed_pieces(
    trace: np.ndarray, resolution: float, side: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Starts and ends (k, 2) of the straight pieces of a slide trace (n, 2) after its first.

    The trace's corners (Douglas-Peucker, tolerance ``resolution`` / 4) are where the surface
    turned; the first piece covers only part of the first contacted edge (its evidence is the
    first contact), every later piece is an edge crossed completely, ending at a corner or at
    the vertex the tool slid off. Pieces shorter than ``resolution`` are dropped, and so are
    pieces that do not run toward ``side`` (the unit normal of the push direction on the slip's
    side): sliding under the load, the tool moves that way along every edge that faces the
    load and slips like the first contact (eq. 12); a piece that does not is a wall or an
    undercut the arm's lateral stiffness pulled the tool along after it passed the lip, and
    would be false evidence. These are the pieces ``core.explore.slide_evidence`` takes from
    the simulated robot's ground truth, read off the robot's own trace. The loop pops at most
    one split per trace point.
    """
    keep, stack = {0, len(trace) - 1}, [(0, len(trace) - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        chord, rel = trace[j] - trace[i], trace[i + 1 : j] - trace[i]
        length = float(np.linalg.norm(chord))
        if length > 0:
            off = np.abs(chord[0] * rel[:, 1] - chord[1] * rel[:, 0]) / length
        else:
            off = np.linalg.norm(rel, axis=1)
        k = int(np.argmax(off))
        if off[k] > resolution / 4:
            keep.add(i + 1 + k)
            stack += [(i, i + 1 + k), (i + 1 + k, j)]
    corners = trace[sorted(keep)]
    a, b = corners[1:-1], corners[2:]
    usable = (np.linalg.norm(b - a, axis=1) >= resolution) & ((b - a) @ side > 0)
    return a[usable], b[usable]


class ForceFilter:
    """F/T bias removal and first-order low-pass filtering of a force vector (newtons).

    The bias is the mean of the first ``bias_samples`` readings after :meth:`reset` (the
    executor resets at the start of every plan, with the tool at rest in free space). After
    that each reading updates ``value`` by an exponential filter with the given cutoff:
    alpha = 1 - exp(-2 pi f_c dt), dt from the reading times.
    """

    def __init__(self, cutoff_hz: float, bias_samples: int) -> None:
        if cutoff_hz <= 0 or bias_samples < 1:
            raise ValueError("cutoff_hz must be > 0 and bias_samples >= 1")
        self.cutoff_hz, self.bias_samples = cutoff_hz, bias_samples
        self.reset()

    def reset(self) -> None:
        self._bias_sum, self._count = 0.0, 0
        self.bias = None
        self.value = None  # an array shaped like the readings once the bias is known
        self._last_t = None

    @property
    def ready(self) -> bool:
        return self.bias is not None

    def add(self, t: float, force: np.ndarray) -> None:
        force = np.asarray(force, float)
        if not self.ready:
            self._bias_sum += force
            self._count += 1
            if self._count == self.bias_samples:
                self.bias = self._bias_sum / self._count
                self.value = np.zeros_like(self.bias)
            self._last_t = t
            return
        dt = max(t - self._last_t, 0.0)
        alpha = 1.0 - np.exp(-2.0 * np.pi * self.cutoff_hz * dt)
        self.value = self.value + alpha * (force - self.bias - self.value)
        self._last_t = t
