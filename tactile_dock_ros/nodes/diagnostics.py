"""The executor's ``/diagnostics`` status (diagnostic_msgs, as ROS drivers publish it).

One ``DiagnosticStatus`` named ``<node>: guarded moves``: ERROR while a sensor stream is older
than ``sensor_timeout`` (or never arrived), WARN while the control loop's longest tick interval
in the last second exceeds two control periods, else OK. Its values: each stream's rate (Hz)
and age (s), the control loop's rate and longest interval, its ticks since start and how many
of them came more than two periods after the previous one (late), the state, the plan counts
(run / refused / aborted), the last fault with its age, and what the caller adds (the
executor: the episode its plans must belong to).
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from tactile_dock_ros.nodes.watchdog import StreamWatch

STREAMS = ("tool_pose", "wrench")


class ExecutorHealth:
    """Counters and stream watches the executor updates; :meth:`status` summarizes them."""

    def __init__(self, sensor_timeout: float, control_period: float) -> None:
        self.sensor_timeout, self.control_period = sensor_timeout, control_period
        self.streams = {name: StreamWatch() for name in STREAMS}
        self.ticks = StreamWatch()
        self.late_ticks = 0  # ticks more than two control periods after the previous one
        self.counts = {"plans_run": 0, "plans_refused": 0, "plans_aborted": 0}
        self.last_fault, self.last_fault_time = "", None

    def tick(self, now: float) -> None:
        """A control-loop tick began at ``now``."""
        if self.ticks.last is not None and now - self.ticks.last > 2.0 * self.control_period:
            self.late_ticks += 1
        self.ticks.add(now)

    def fault(self, now: float, detail: str) -> None:
        self.last_fault, self.last_fault_time = detail, now

    def oldest(self, now: float) -> tuple[str, float]:
        """(name, age s) of the older of the two streams (age inf until both arrived)."""
        return max(((n, w.age(now)) for n, w in self.streams.items()), key=lambda x: x[1])

    def status(
        self, now: float, name: str, state: str, extra: dict[str, str] | None = None
    ) -> DiagnosticStatus:
        values = {}
        stale = []
        for stream, watch in self.streams.items():
            age = watch.age(now)
            values[f"{stream}_rate_hz"] = f"{watch.rate(now):.1f}"
            values[f"{stream}_age_s"] = f"{age:.3f}"
            if age > self.sensor_timeout:
                why = "missing" if watch.last is None else f"stale {age:.2f} s"
                stale.append(f"{stream} {why}")
        gap = self.ticks.max_gap(now)
        values["control_rate_hz"] = f"{self.ticks.rate(now):.1f}"
        values["control_max_period_s"] = f"{gap:.4f}"
        values["control_ticks"] = str(self.ticks.count)
        values["control_late_ticks"] = str(self.late_ticks)
        values["state"] = state
        values.update({k: str(v) for k, v in self.counts.items()})
        values["last_fault"] = self.last_fault
        fault_age = "" if self.last_fault_time is None else f"{now - self.last_fault_time:.1f}"
        values["last_fault_age_s"] = fault_age
        values.update(extra or {})
        if stale:
            level, message = DiagnosticStatus.ERROR, "; ".join(stale)
        elif gap > 2.0 * self.control_period:
            level, message = DiagnosticStatus.WARN, f"control loop late: {gap * 1e3:.0f} ms tick"
        else:
            level, message = DiagnosticStatus.OK, state
        return DiagnosticStatus(
            level=level,
            name=f"{name}: guarded moves",
            message=message,
            hardware_id=name,
            values=[KeyValue(key=k, value=v) for k, v in values.items()],
        )
