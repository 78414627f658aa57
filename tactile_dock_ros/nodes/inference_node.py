"""inference: the contact history and posterior shape samples (paper Sec. IV).

Subscribes ``terrain_prior`` (ShapeDistribution, latched), ``execution_report`` (only reports of
the current episode count) and ``episode`` (std_msgs/UInt32, latched: the planner's episode id;
a new id empties the history). Keeps the
history, publishes it latched on ``contact_history`` and, after every change while an episode
runs, samples the posterior with ``core.sampling.sample_posterior`` and publishes
``shape_samples`` (latched) and RViz markers on ``~/markers``.
"""

from __future__ import annotations

import numpy as np
from rclpy.node import Node
from std_msgs.msg import UInt32
from visualization_msgs.msg import MarkerArray

from tactile_dock_ros.core.history import History
from tactile_dock_ros.core.sampling import NODE_METHODS, sample_posterior
from tactile_dock_ros.msg import ContactHistory, ExecutionReport, ShapeDistribution, ShapeSamples
from tactile_dock_ros.nodes import convert, markers, qos
from tactile_dock_ros.nodes.common import guarded, header, run
from tactile_dock_ros.nodes.params import Param, declare

PARAMS = [
    Param(
        "method",
        "hmc",
        "posterior sampler (not mh: a benchmark baseline whose chains barely move)",
        choices=NODE_METHODS,
    ),
    Param("num_samples", 100, "posterior samples per cycle", "", 2, 100000),
    Param("seed", 0, "seed of the sampler's random generator", "", 0, 2**31 - 1),
    Param("marker_samples", 20, "samples drawn as RViz line strips", "", 0, 1000),
]


class InferenceNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("inference", **kwargs)
        self.p = declare(self, PARAMS)
        self.rng = np.random.default_rng(self.p.seed)
        self.prior = None
        self.last_z = None  # (N, m) previous posterior in z, for the sampler's warm start
        self.frame_id = "dock_plane"
        self.history = History()
        self.plan_ids = np.zeros(0, int)
        self.handled_plans: set[int] = set()
        self.episode = 0
        self.history_pub = self.create_publisher(ContactHistory, "contact_history", qos.LATCHED)
        self.samples_pub = self.create_publisher(ShapeSamples, "shape_samples", qos.LATCHED)
        self.marker_pub = self.create_publisher(MarkerArray, "~/markers", qos.LATCHED)
        self.create_subscription(
            ShapeDistribution, "terrain_prior", guarded(self, "prior", self.on_prior), qos.LATCHED
        )
        self.create_subscription(
            ExecutionReport, "execution_report", guarded(self, "report", self.on_report), qos.EVENTS
        )
        self.create_subscription(UInt32, "episode", self.on_episode, qos.LATCHED)

    def on_prior(self, msg: ShapeDistribution) -> None:
        self.prior = convert.shape_from_msg(msg)
        self.last_z = None
        self.frame_id = msg.header.frame_id or self.frame_id
        self.get_logger().info(
            f"prior: {self.prior.n_vertices} vertices, {self.prior.n_basis} basis columns"
        )
        self.update()

    def on_episode(self, msg: UInt32) -> None:
        if msg.data == self.episode:
            return
        self.episode = msg.data
        self.history, self.plan_ids = History(), np.zeros(0, int)
        self.last_z = None
        self.handled_plans.clear()
        self.get_logger().info(f"episode {self.episode}: history cleared")
        self.update()

    def on_report(self, msg: ExecutionReport) -> None:
        report = convert.report_from_msg(msg)
        if report.episode != self.episode:
            self.get_logger().warning(
                f"plan {report.plan_id} of episode {report.episode}: report ignored (the current "
                f"episode is {self.episode})"
            )
            return
        if report.plan_id in self.handled_plans:
            self.get_logger().warning(f"plan {report.plan_id}: duplicate report ignored")
            return
        self.handled_plans.add(report.plan_id)
        new = report.history
        self.history = self.history.extend(new.a, new.b, new.status)
        self.plan_ids = np.concatenate([self.plan_ids, np.full(len(new), report.plan_id)])
        self.update()

    def update(self) -> None:
        """Publish the history; sample and publish the posterior when an episode runs."""
        stamp = header(self, self.frame_id)
        self.history_pub.publish(convert.history_to_msg(self.history, stamp, self.plan_ids))
        if self.prior is None or self.episode == 0:
            return
        try:
            posterior = sample_posterior(
                self.prior,
                self.history,
                self.p.num_samples,
                self.rng,
                method=self.p.method,
                init_z=self.last_z,  # warm start from the previous cycle's posterior
            )
            vertices = posterior.vertices
            self.last_z = posterior.z if len(posterior.z) else None
        except (ValueError, RuntimeError) as err:  # e.g. no state consistent with the history
            self.get_logger().error(f"posterior sampling failed: {err}")
            vertices = np.zeros((0, self.prior.n_vertices, 2))
        if len(vertices) < 2:  # the planner needs two (moment fit); tell it there are none
            self.get_logger().error(f"{len(vertices)} posterior samples: publishing an empty set")
            self.samples_pub.publish(
                convert.samples_to_msg(
                    vertices[:0], header(self, self.frame_id), self.p.method, 0.0, len(self.history)
                )
            )
            return
        self.samples_pub.publish(
            convert.samples_to_msg(
                posterior.vertices,
                header(self, self.frame_id),
                posterior.method,
                posterior.ess,
                len(self.history),
                posterior.dropped,
                posterior.seconds,
            )
        )
        self.marker_pub.publish(
            markers.samples_and_history(
                posterior.vertices[: self.p.marker_samples], self.history, stamp
            )
        )
        self.get_logger().info(
            f"episode {self.episode} cycle {len(self.handled_plans) + 1}: history "
            f"{len(self.history)} segments, {len(posterior.vertices)} {posterior.method} samples, "
            f"ESS {posterior.ess:.1f}, R-hat {posterior.convergence.rhat:.3f}, "
            f"{posterior.seconds:.3f} s, dropped {len(posterior.dropped)}"
        )
        check = posterior.convergence
        if check.reseeded or not check.converged:
            self.get_logger().warning(
                f"posterior chains disagreed: {check.reseeded} trapped chains re-seeded in "
                f"{check.rounds} rounds, {check.trapped} still trapped, split R-hat "
                f"{check.rhat:.3f} (limit {check.rhat_limit:.3f})"
            )


def main(args: list[str] | None = None) -> int:
    return run(InferenceNode, args)
