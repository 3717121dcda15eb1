"""Declare parameters from a plain table: descriptor, range, read-only flag, one place.

A node lists :class:`ParamSpec` rows; :func:`declare` turns them into declared parameters with
``ParameterDescriptor`` (description, ranges, read_only). The same rows produce the README table
and are checked against ``config/<node>.yaml`` by the tests, so defaults live in one place.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import gc
import signal
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.executors import (
    ExternalShutdownException,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.utilities import ok as context_ok
from rclpy.utilities import remove_ros_args, try_shutdown

from transparency_ros.core.errors import ConfigError, TransparencyError


class ParameterError(ConfigError):
    """A node parameter whose value (or name) the node does not know; the message names it."""


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: Any
    description: str
    read_only: bool = False
    low: float | None = None
    high: float | None = None
    choices: Sequence[str] = ()

    def error(self, value: Any) -> str | None:
        """Why ``value`` is not one this parameter accepts (choices), or None."""
        if self.choices and value not in self.choices:
            return f"{self.name} must be one of {list(self.choices)}, got {value!r}"
        return None

    def accepts(self) -> str:
        """What this parameter accepts, in words."""
        kind = {bool: "a bool", int: "an integer", float: "a number", str: "a string"}.get(
            type(self.default), f"a list like {self.default!r}"
        )
        if self.choices:
            return f"one of {list(self.choices)}"
        if self.low is not None and self.high is not None and not isinstance(self.default, bool):
            return f"{kind} in [{self.low:g}, {self.high:g}]"
        return kind

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


def _is_double(spec: ParamSpec) -> bool:
    return isinstance(spec.default, float)


def _as_double(param: Parameter) -> Parameter:
    """An integer given for a double parameter (``k_s:=5``, as ROS users type it) as a double;
    anything else unchanged (a wrong type is then refused by rclpy, and named by us)."""
    if param.type_ == Parameter.Type.INTEGER:
        return Parameter(param.name, Parameter.Type.DOUBLE, float(param.value))
    return param


def declare(node: Node, specs: Iterable[ParamSpec]) -> dict[str, Any]:
    """Declare every spec on ``node``; return {name: value} as given (overrides included).

    An integer override of a double parameter is taken as the double it means. A value of the
    wrong type, out of range or not one of the parameter's choices raises :class:`ParameterError`
    naming the parameter and what it accepts: a node never starts on a value it does not know.
    """
    values: dict[str, Any] = {}
    overrides: dict[str, Parameter] = getattr(node, "_parameter_overrides", {})
    for spec in specs:
        if _is_double(spec) and spec.name in overrides:
            overrides[spec.name] = _as_double(overrides[spec.name])
        try:
            param = node.declare_parameter(spec.name, spec.default, spec.descriptor())
        except ParameterException as err:
            given = overrides.get(spec.name)
            shown = f"{given.value!r} ({given.type_.name.lower()})" if given else "a value"
            raise ParameterError(
                f"parameter {spec.name}: got {shown}, expected {spec.accepts()}"
            ) from err
        reason = spec.error(param.value)
        if reason:
            raise ParameterError(f"parameter {reason}")
        values[spec.name] = param.value
    return values


def accept_integers_for_doubles(node: Node, specs: Iterable[ParamSpec]) -> None:
    """At runtime too (``ros2 param set /node k_s 5``): an integer for a double is a double."""
    doubles = {spec.name for spec in specs if _is_double(spec)}

    def convert(params: list[Parameter]) -> list[Parameter]:
        return [_as_double(p) if p.name in doubles else p for p in params]

    node.add_pre_set_parameters_callback(convert)


def unknown_overrides(node: Node) -> list[str]:
    """Parameters given to ``node`` (``-p``, a parameter file) that it never declared: a
    misspelt name would otherwise leave the default in force without a word."""
    overrides: dict[str, Parameter] = getattr(node, "_parameter_overrides", {})
    return sorted(
        name
        for name in overrides
        if not node.has_parameter(name) and not name.startswith("qos_overrides.")
    )


def check_unknown(node: Node, *, refuse: bool, renamed: dict[str, str] | None = None) -> None:
    """Refuse (nodes that command motors) or warn about parameters the node does not know;
    ``renamed``: old name -> what replaced it, said with it."""
    unknown = unknown_overrides(node)
    if not unknown:
        return
    hints = [
        f"{name} is now {(renamed or {})[name]}" for name in unknown if name in (renamed or {})
    ]
    text = f"unknown parameter(s) {unknown} (see --help for this node's parameters)"
    if hints:
        text += ": " + "; ".join(hints)
    if refuse:
        raise ParameterError(text)
    node.get_logger().warning(text + ": ignored")


def choice_error(specs: Iterable[ParamSpec], name: str, value: Any) -> str | None:
    """Reason a string parameter's value is not one of its choices, or None."""
    for spec in specs:
        if spec.name == name:
            return spec.error(value)
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


NodeT = TypeVar("NodeT", bound=Node)


def destroyed_if_refused(cls: type[NodeT]) -> type[NodeT]:
    """Class decorator: a node whose constructor raises (a refused parameter, a bad file) after
    ``Node.__init__`` has made its DDS entities is made safe (``make_safe``, if it has one) and
    destroyed before the error propagates. Left to the garbage collector, the half-built node's
    entities were torn down at some later moment, under a context being shut down or at
    interpreter exit, while other participants of the process were running."""
    init = cls.__init__

    @functools.wraps(init)
    def init_or_undo(self: Node, *args: Any, **kwargs: Any) -> None:
        try:
            init(self, *args, **kwargs)
        except BaseException:
            # Node.__init__ itself may have failed: then there is nothing (or less) to undo
            with contextlib.suppress(Exception):
                getattr(self, "make_safe", lambda: None)()
            try:
                self.destroy_node()
            except Exception:  # noqa: BLE001 - an override may need what was never built
                with contextlib.suppress(Exception):
                    super(cls, self).destroy_node()  # type: ignore[misc]
            raise

    cls.__init__ = init_or_undo  # type: ignore[method-assign]
    return cls


def freeze_startup() -> None:
    """What start-up created stays out of the garbage collector: a full collection then takes
    well under a millisecond instead of 10-36 ms, during which no thread of the process runs (a
    stall every subscriber of a 1-10 kHz node, and the driver's hardware loop, would see)."""
    gc.collect()
    gc.freeze()


class QuietSingleThreadedExecutor(SingleThreadedExecutor):
    """rclpy's executor, whose ``__del__`` holds where a shutdown struck its constructor. A
    signal shuts the context down from rclpy's handler thread at any moment (no signal mask
    of the main thread holds it off: it is delivered to any thread), also while an executor
    is built: its constructor raises (caught by the node's main as the same shutdown) before
    it sets ``_sigint_gc``, which ``Executor.__del__`` reads, and an "Exception ignored"
    traceback was printed (test_shutdown, SIGTERM 1.5 s after the estimator's start, the
    machine loaded). The class's value stands in until the constructor sets its own."""

    _sigint_gc = None  # type: ignore[assignment]  # (rclpy sets None itself on shutdown)


class QuietMultiThreadedExecutor(MultiThreadedExecutor):
    """:class:`QuietSingleThreadedExecutor`'s mend on the driver's two-thread executor."""

    _sigint_gc = None  # type: ignore[assignment]  # (rclpy sets None itself on shutdown)


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
    # Ctrl-C: rclpy's own handler shuts the context down and wakes the executor, and spin
    # ends. Python's KeyboardInterrupt, which it also let through, struck at whatever line ran:
    # inside rclpy taking a message (a RuntimeError from pybind11, exit 1) or making a Task (an
    # "Exception ignored" traceback), about 1 in 5 Ctrl-Cs of the sweeping behavior. A no-op
    # Python handler, installed before rclpy's so that its handler chains to it, leaves the
    # shutdown to the context alone.
    previous = signal.signal(signal.SIGINT, lambda *_: None)
    rclpy.init(args=None if args is None else list(args))
    node: Node | None = None
    try:
        node = make_node()
        freeze_startup()
        executor = QuietSingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _rclpy.RCLError:
        # a signal shuts the context down; the executor may be building its wait set just then
        # ("the given context is not valid"): the same shutdown, not a failure
        if context_ok():
            raise
    except TransparencyError as err:
        print(f"{name}: error: {err}", file=sys.stderr)  # noqa: T201
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        try_shutdown()
        signal.signal(signal.SIGINT, previous)
    return 0
