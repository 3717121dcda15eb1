"""Ground truth of the simulated feel-cage rail, offered by ``actuator_driver`` over ROS.

With ``sim_environment:=ball_on_rail`` the driver's simulated actuator strikes a ball on a rail
(:mod:`transparency_ros.core.ball_on_rail`). What a lab measures with a camera or a light gate,
the simulation knows exactly; this interface publishes it so that an experiment run through the
real nodes can be scored against the truth (standard interfaces only):

* ``~/sim/place_ball`` (std_srvs/Trigger): put a fresh ball at rest on the rail, if the arm is
  clear of it (fails with the reason otherwise; retry once the arm has passed);
* ``~/sim/ball`` (diagnostic_msgs/DiagnosticStatus, latched) at ``rate_hz`` and after every
  placement. ``message`` is one of
  ``no ball``, ``resting``, ``struck``, ``lost``; ``values``: ``placed``, ``x_m``, ``v_m_s``,
  ``contacts``, ``max_force_n``, ``first_contact_stamp_s`` and ``exit_stamp_s`` (ROS time of the
  first arm-ball contact and of the ball passing the workspace exit; empty until they happen).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_srvs.srv import Trigger

from transparency_ros.canbus.sim_device import SimulatedActuator
from transparency_ros.core.ball_on_rail import BallOnRail

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


class SimBallInterface:
    """Service and truth topic for a :class:`BallOnRail` inside a simulated actuator."""

    def __init__(
        self,
        node: Node,
        get_sim: Callable[[], SimulatedActuator | None],
        ros_seconds_at: Callable[[float], float],
        rate_hz: float = 20.0,
    ) -> None:
        self.node, self.get_sim, self.ros_seconds_at = node, get_sim, ros_seconds_at
        self._pub = node.create_publisher(DiagnosticStatus, "~/sim/ball", LATCHED)
        node.create_service(Trigger, "~/sim/place_ball", self._on_place)
        node.create_timer(1.0 / rate_hz, self.publish)

    def _rail(self) -> tuple[SimulatedActuator, BallOnRail] | None:
        sim = self.get_sim()
        if sim is None or not isinstance(sim.physics.environment, BallOnRail):
            return None
        return sim, sim.physics.environment

    def _on_place(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        rail = self._rail()
        if rail is None:
            response.success, response.message = False, "no simulated rail (not configured)"
            return response
        sim, env = rail
        with sim.lock:
            env.placed = False  # a fresh ball, at rest
            placed = env.place(sim.physics.output_position_rad)
        response.success = placed
        response.message = "ball placed" if placed else "the arm is over the rail; retry"
        self.publish()
        return response

    def publish(self) -> None:
        rail = self._rail()
        if rail is None:
            return
        sim, env = rail
        with sim.lock:
            s, placed = env.state, env.placed
            values = {
                "placed": str(placed).lower(),
                "x_m": f"{s.x_m:.6f}",
                "v_m_s": f"{s.v_m_s:.6f}",
                "contacts": str(s.contacts),
                "max_force_n": f"{s.max_force_n:.3f}",
                "first_contact_stamp_s": self._stamp(sim, s.first_contact_s),
                "exit_stamp_s": self._stamp(sim, s.exit_s),
            }
            lost = env.lost
        message = (
            "no ball"
            if not placed
            else "lost"
            if lost
            else "struck"
            if values["first_contact_stamp_s"]
            else "resting"
        )
        status = DiagnosticStatus(name="ball_on_rail", message=message, level=DiagnosticStatus.OK)
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        self._pub.publish(status)

    def _stamp(self, sim: SimulatedActuator, physics_s: float | None) -> str:
        if physics_s is None:
            return ""
        return f"{self.ros_seconds_at(sim.start_monotonic_s + physics_s):.9f}"
