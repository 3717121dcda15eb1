"""The simulated drop-test rig's DAQ and trigger, offered by ``actuator_driver`` over ROS.

With ``sim_environment:=drop_rig`` the simulated actuator's arm is struck by a shuttle falling on
a vertical rail (:mod:`transparency_ros.core.drop_rig`). The rig's own instruments are a DAQ, as
in the paper (load cell and potentiometer at 10 kHz); publishing 20 000 messages a second from
Python would starve the driver loop, so the DAQ publishes blocks, as DAQ drivers do, and
``transparency rig`` writes them into the bag as the contract's per-sample topics:

* ``~/sim/lift`` (std_srvs/Trigger): take the shuttle off the arm and hold it with its face
  ``sim_drop_height_m`` (a runtime parameter) above the arm tip;
* ``~/sim/drop`` (std_srvs/Trigger): let it go (lifted first if it is not held);
* ``~/sim/daq`` (std_msgs/Float64MultiArray), every ``1 / rate_hz`` s while samples exist:
  layout dim[0] ``sample`` (rows), dim[1] ``stamp_sec,stamp_frac_s,force_n,height_m`` (4
  columns): the ROS time of each 10 kHz sample as whole seconds and fraction (one float64 would
  round it to 0.24 us), the load-cell force [N] and the height of the shuttle's contact face
  above the arm tip at rest [m], both with the rig's sensor noise.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from std_srvs.srv import Trigger

from transparency_ros.canbus.sim_device import SimulatedActuator
from transparency_ros.core.drop_rig import DropRig
from transparency_ros.core.errors import ModelError

DAQ_COLUMNS = ("stamp_sec", "stamp_frac_s", "force_n", "height_m")


class SimRigInterface:
    def __init__(
        self,
        node: Node,
        get_sim: Callable[[], SimulatedActuator | None],
        ros_seconds_at: Callable[[float], float],
        drop_height: Callable[[], float],
        rate_hz: float = 100.0,
    ) -> None:
        self.get_sim, self.ros_seconds_at, self.drop_height = get_sim, ros_seconds_at, drop_height
        self._pub = node.create_publisher(Float64MultiArray, "~/sim/daq", 100)
        node.create_service(Trigger, "~/sim/lift", self._on_lift)
        node.create_service(Trigger, "~/sim/drop", self._on_drop)
        node.create_timer(1.0 / rate_hz, self.publish)

    def _rig(self) -> tuple[SimulatedActuator, DropRig] | None:
        sim = self.get_sim()
        if sim is None or not isinstance(sim.physics.environment, DropRig):
            return None
        return sim, sim.physics.environment

    def _on_lift(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        return self._act(response, lift=True)

    def _on_drop(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        return self._act(response, lift=False)

    def _act(self, response: Trigger.Response, *, lift: bool) -> Any:
        rig = self._rig()
        if rig is None:
            response.success, response.message = False, "no simulated rig (not configured)"
            return response
        sim, env = rig
        height = self.drop_height()
        try:
            with sim.lock:
                if lift:
                    env.hold(height)
                elif env.state.released or env.state.height_m <= 0.0:
                    env.release(height)  # not held: lift to the set height, then let go
                else:
                    env.release()  # from where it is held
                    height = env.state.height_m
        except ModelError as err:
            response.success, response.message = False, str(err)
            return response
        what = "held at" if lift else "released from"
        response.success, response.message = True, f"shuttle {what} {height:.4f} m"
        return response

    def publish(self) -> None:
        rig = self._rig()
        if rig is None:
            return
        sim, env = rig
        with sim.lock:
            samples = env.take_daq()
        if not samples:
            return
        msg = Float64MultiArray()
        n, k = len(samples), len(DAQ_COLUMNS)
        msg.layout.dim = [
            MultiArrayDimension(label="sample", size=n, stride=k * n),
            MultiArrayDimension(label=",".join(DAQ_COLUMNS), size=k, stride=k),
        ]
        # ROS time of physics time 0, split so that adding a sample's time keeps precision
        origin = self.ros_seconds_at(sim.start_monotonic_s)
        whole = math.floor(origin)
        data: list[float] = []
        for s in samples:
            frac = (origin - whole) + s.time_s
            carry = math.floor(frac)
            data += [float(whole + carry), frac - carry, s.force_n, s.height_m]
        msg.data = data
        self._pub.publish(msg)
