"""Every custom message crosses a process boundary over DDS with all field values intact."""

import subprocess
import sys

import message_samples
import pytest
from conftest import TEST_DIR
from publish_message_samples import LATCHED
from ros_helpers import ros_node, spin_until

pytestmark = pytest.mark.dds


def test_every_message_round_trips_between_processes():
    expected = message_samples.build()
    publisher = subprocess.Popen(
        [sys.executable, str(TEST_DIR / "publish_message_samples.py")],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    received = {}
    try:
        with ros_node("message_sample_receiver") as (node, executor):
            for name, msg in expected.items():
                node.create_subscription(
                    type(msg),
                    f"/roundtrip/{name}",
                    lambda m, name=name: received.setdefault(name, m),
                    LATCHED,
                )
            spin_until(executor, lambda: len(received) == len(expected), timeout_s=60.0)
    finally:
        try:
            _, err = publisher.communicate(input="", timeout=30)  # closing stdin ends it
        except subprocess.TimeoutExpired:
            publisher.kill()
            _, err = publisher.communicate()
    assert publisher.returncode == 0, err
    assert sorted(received) == sorted(expected), f"missing: {set(expected) - set(received)}"
    for name, msg in expected.items():
        assert received[name] == msg, name


def test_sample_messages_use_non_default_values():
    """Guards the round trip test: a default-valued field would compare equal trivially."""
    for name, msg in message_samples.build().items():
        default = type(msg)()
        for field in msg.get_fields_and_field_types():
            assert getattr(msg, field) != getattr(default, field), f"{name}.{field}"
