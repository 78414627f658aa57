"""Declare, validate and log node parameters from one table per node.

Every parameter gets a ``ParameterDescriptor`` (description with its unit, and a numeric range
where one applies), so ``ros2 param describe`` documents it; values are validated once at start
(range, choices, list length, finite numbers) and logged with their units. A bad value raises
``ValueError`` naming the parameter, which stops the node before it touches any hardware. Every
parameter is read-only: the nodes read them once, so ``ros2 param set`` is refused rather than
accepted and silently ignored (restart the node with new values).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterValueException, ParameterException
from rclpy.node import Node


@dataclass(frozen=True)
class Param:
    """One parameter: default (its type fixes the parameter type), unit, bounds (inclusive)."""

    name: str
    default: object
    description: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    length: int | None = None  # required length of a list parameter

    def descriptor(self) -> ParameterDescriptor:
        text = f"{self.description} [{self.unit}]" if self.unit else self.description
        if self.choices:
            text += f" (one of: {', '.join(self.choices)})"
        if isinstance(self.default, list) and self.low is not None and self.high is not None:
            text += f" (each in [{self.low:g}, {self.high:g}])"  # ROS ranges are scalar only
        descriptor = ParameterDescriptor(name=self.name, description=text, read_only=True)
        if self.low is not None and self.high is not None and not isinstance(self.default, list):
            if isinstance(self.default, bool):
                pass
            elif isinstance(self.default, int):
                descriptor.integer_range = [
                    IntegerRange(from_value=int(self.low), to_value=int(self.high), step=1)
                ]
            elif isinstance(self.default, float):
                descriptor.floating_point_range = [
                    FloatingPointRange(from_value=self.low, to_value=self.high, step=0.0)
                ]
        return descriptor

    def check(self, value) -> None:
        values = value if isinstance(value, list | tuple) else [value]
        if self.length is not None and len(values) != self.length:
            raise ValueError(f"parameter {self.name}: needs {self.length} values, got {value}")
        if self.choices and value not in self.choices:
            raise ValueError(f"parameter {self.name}: {value!r} is not one of {self.choices}")
        for v in values:
            if isinstance(v, int | float) and not isinstance(v, bool):
                if not math.isfinite(v):
                    raise ValueError(f"parameter {self.name}: {value} is not finite")
                if self.low is not None and v < self.low:
                    raise ValueError(f"parameter {self.name}: {value} is below {self.low}")
                if self.high is not None and v > self.high:
                    raise ValueError(f"parameter {self.name}: {value} is above {self.high}")


def declare(node: Node, table: list[Param]) -> SimpleNamespace:
    """Declare every parameter of ``table`` on ``node``; return their validated values. A
    parameter declared before (a lifecycle node's configure after a cleanup or a failed
    configure) is read again, not declared twice: its read-only value is validated again."""
    values = {}
    for param in table:
        try:
            if node.has_parameter(param.name):  # a lifecycle node configured again
                declared = node.get_parameter(param.name)
            else:
                declared = node.declare_parameter(param.name, param.default, param.descriptor())
        except (InvalidParameterValueException, ParameterException, TypeError) as err:
            raise ValueError(f"parameter {param.name}: {err}") from err
        value = declared.value
        if isinstance(value, list | tuple):  # array parameters arrive as array.array / tuples
            value = list(value)
        param.check(value)
        values[param.name] = value
        node.get_logger().info(f"param {param.name} = {value} {param.unit}".rstrip())
    return SimpleNamespace(**values)
