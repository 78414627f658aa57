"""Publisher process for test_messages_dds: publishes every sample message, latched, and stays
up until its standard input closes (the test closes it) or 120 s pass."""

import select
import sys
import time

import message_samples
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

LATCHED = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("message_sample_publisher")
    publishers = []
    for name, msg in message_samples.build().items():
        pub = node.create_publisher(type(msg), f"/roundtrip/{name}", LATCHED)
        pub.publish(msg)
        publishers.append(pub)
    print("published", flush=True)
    deadline = time.monotonic() + 120.0
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
        if select.select([sys.stdin], [], [], 0)[0] and not sys.stdin.read(1):
            break
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
