"""``main`` of ``actuator_driver``: the node on a two-thread executor; one line and status 2
for a configuration or bus error; every exit path leaves the motors disabled."""

from __future__ import annotations

import sys

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.utilities import ok as context_ok
from rclpy.utilities import try_shutdown

from transparency_ros.canbus.errors import CanProtocolError
from transparency_ros.core.errors import TransparencyError
from transparency_ros.ros.actuator_driver.node import ActuatorDriverNode
from transparency_ros.ros.actuator_driver.parameters import (
    DESCRIPTION,
    NODE_NAME,
    PARAMETERS,
    exit_logger,
)
from transparency_ros.ros.params import (
    QuietMultiThreadedExecutor,
    freeze_startup,
    parse_node_cli,
)


def main(args: list[str] | None = None) -> int:
    parse_node_cli(NODE_NAME, DESCRIPTION, PARAMETERS, args)
    rclpy.init(args=args)
    node: ActuatorDriverNode | None = None
    try:
        node = ActuatorDriverNode()
        freeze_startup()
        node.gc_pauses.durations.reset()  # from here on: the collections while running
        executor = QuietMultiThreadedExecutor(num_threads=2)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _rclpy.RCLError:
        # a signal can shut the context down while a MultiThreadedExecutor worker rebuilds its
        # wait set ("the given context is not valid"): that is the same shutdown, not a failure
        if context_ok():
            raise
    except (CanProtocolError, TransparencyError) as err:
        print(f"{NODE_NAME}: error: {err}", file=sys.stderr)  # noqa: T201
        return 2
    finally:
        if node is not None:
            node.make_safe()
            exit_logger().info("shut down: motor disabled, bus closed")
            node.destroy_node()
        try_shutdown()
    return 0
