"""Declare parameters from a plain table: descriptor, range, read-only flag, one place.

A node lists :class:`ParamSpec` rows; :func:`declare` turns them into declared parameters with
``ParameterDescriptor`` (description, ranges, read_only). The same rows produce the README table
and are checked against ``config/<node>.yaml`` by the tests, so defaults live in one place.
"""

from __future__ import annotations

import argparse
import gc
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import remove_ros_args, try_shutdown

from transparency_ros.core.errors import TransparencyError


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: Any
    description: str
    read_only: bool = False
    low: float | None = None
    high: float | None = None
    choices: Sequence[str] = ()

    def descriptor(self) -> ParameterDescriptor:
        desc = ParameterDescriptor(description=self.description, read_only=self.read_only)
        if self.choices:
            desc.additional_constraints = "one of: " + ", ".join(self.choices)
        if self.low is not None and self.high is not None:
            if isinstance(self.default, bool):
                pass
            elif isinstance(self.default, int):
                desc.integer_range = [
                    IntegerRange(from_value=int(self.low), to_value=int(self.high), step=0)
                ]
            elif isinstance(self.default, float):
                desc.floating_point_range = [
                    FloatingPointRange(
                        from_value=float(self.low), to_value=float(self.high), step=0.0
                    )
                ]
        return desc


def declare(node: Node, specs: Iterable[ParamSpec]) -> dict[str, Any]:
    """Declare every spec on ``node``; return {name: value} as given (overrides included)."""
    values: dict[str, Any] = {}
    for spec in specs:
        param = node.declare_parameter(spec.name, spec.default, spec.descriptor())
        values[spec.name] = param.value
    return values


def choice_error(specs: Iterable[ParamSpec], name: str, value: Any) -> str | None:
    """Reason a string parameter's value is not one of its choices, or None."""
    for spec in specs:
        if spec.name == name and spec.choices and value not in spec.choices:
            return f"{name} must be one of {list(spec.choices)}, got {value!r}"
    return None


def parse_node_cli(
    name: str, description: str, specs: Sequence[ParamSpec], argv: Sequence[str] | None
) -> None:
    """``--help`` for a node: its purpose and every parameter. ROS arguments pass through."""
    rows = []
    for spec in specs:
        extra = " (read-only)" if spec.read_only else ""
        if spec.choices:
            extra += f" one of {list(spec.choices)}"
        elif spec.low is not None:
            extra += f" range [{spec.low:g}, {spec.high:g}]"
        rows.append(f"  {spec.name} = {spec.default!r}: {spec.description}{extra}")
    parser = argparse.ArgumentParser(
        prog=name,
        description=description,
        epilog="parameters (set with --ros-args -p name:=value or --params-file FILE):\n"
        + "\n".join(rows),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.parse_args(remove_ros_args(list(sys.argv if argv is None else argv))[1:])


def run_node(
    name: str,
    description: str,
    specs: Sequence[ParamSpec],
    make_node: Callable[[], Node],
    args: Sequence[str] | None,
) -> int:
    """``main`` of a single-threaded node, as in ros2/demos: --help, spin, clean shutdown on
    Ctrl-C or SIGTERM, one line and status 2 for a configuration error."""
    parse_node_cli(name, description, specs, args)
    rclpy.init(args=None if args is None else list(args))
    node: Node | None = None
    try:
        node = make_node()
        # what start-up created stays out of the collector: its full collections then take
        # ~1 ms instead of 10-25 ms, a stall every subscriber of a 1-10 kHz node would see
        gc.collect()
        gc.freeze()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except TransparencyError as err:
        print(f"{name}: error: {err}", file=sys.stderr)  # noqa: T201
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        try_shutdown()
    return 0
