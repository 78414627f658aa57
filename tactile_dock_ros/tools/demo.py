"""make demo: bring up the mock profile, run one docking episode, report and plot it.

    python -m tactile_dock_ros.tools.demo [--problem sloper] [--seed 0] [--png episode.png]
        [--bag DIR [--storage mcap|sqlite3]]

Starts the five nodes of ``launch/tactile_dock.launch.xml profile:=mock`` as processes (what
``ros2 launch`` would start), sends an empty goal to ``/dock``, prints one line per cycle, the
result and the latency breakdown, writes the episode figure, and exits 0 only when the tool
DOCKED.
Node logs go to ``--log-dir``; ``--bag DIR`` also records the episode's topics as a rosbag2 bag
for ``python -m tactile_dock_ros.tools.replay DIR`` (MCAP by default, with the QoS each topic's
publishers offered, so ``ros2 bag play DIR`` replays the latched topics latched).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from tactile_dock_ros.perception.prior_select import PRIOR_SOURCES, SOURCE_ALIASES


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--problem", default="sloper", help="benchmark problem of the terrain")
    parser.add_argument("--seed", type=int, default=0, help="seed of the ground-truth draw")
    parser.add_argument(
        "--prior-source",
        default="depth",
        choices=(*PRIOR_SOURCES, *SOURCE_ALIASES),
        help="perception's prior_source: depth (the shipped terrain classes conditioned on the "
        "depth image), generic (the generic depth prior alone) or problem (the hand-made prior)",
    )
    parser.add_argument("--png", type=Path, default=Path("episode.png"))
    parser.add_argument("--log-dir", type=Path, default=None, help="node logs (default: temp)")
    parser.add_argument("--bag", type=Path, default=None, help="record a rosbag2 bag here (new)")
    parser.add_argument("--storage", default="mcap", choices=("mcap", "sqlite3"), help="bag")
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds for the episode")
    args = parser.parse_args(argv)
    if args.bag is not None and args.bag.exists():
        parser.error(f"--bag {args.bag} exists; rosbag2 never overwrites a bag")
    from tactile_dock_ros.tools import bringup

    bringup.isolate_dds(keep_domain=True)  # before rclpy loads

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from tactile_dock_ros.tools import episode

    log_dir = args.log_dir or Path(tempfile.mkdtemp(prefix="tactile_dock_demo_"))
    arguments = {
        "profile": "mock",
        "problem": args.problem,
        "seed": str(args.seed),
        "prior_source": args.prior_source,
    }
    print(f"mock profile: problem {args.problem}, seed {args.seed}, prior from {args.prior_source}")
    print(f"node logs: {log_dir}")
    rclpy.init()
    client = episode.EpisodeClient()
    executor = SingleThreadedExecutor()
    executor.add_node(client)
    try:
        with bringup.running(arguments, log_dir):
            record = client.run(executor, args.timeout)
    except (TimeoutError, RuntimeError) as err:
        print(f"demo failed: {err} (see the node logs in {log_dir})")
        return 1
    finally:
        executor.shutdown()
        client.destroy_node()
        rclpy.shutdown()
    why = record.detail if record.status is not None else "no episode status"
    print(f"result: {record.state} after {len(record.plans)} cycles ({why})")
    print(episode.latency_table(record))
    episode.plot(record, args.png)
    print(f"wrote {args.png}")
    if args.bag is not None:
        from tactile_dock_ros.tools import bag

        count = bag.write(args.bag, record.messages, args.storage, record.offered_qos)
        print(
            f"wrote {count} messages to {args.bag}; "
            f"replay: python -m tactile_dock_ros.tools.replay {args.bag}"
        )
    return 0 if record.state == "DOCKED" else 1


if __name__ == "__main__":
    sys.exit(main())
