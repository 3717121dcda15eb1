"""Lifecycle node ``actuator_driver``: a CAN actuator as sensor_msgs/JointState.

One concern a file:

* ``parameters``  the parameter table (names, defaults, ranges, which apply at runtime);
* ``hardware``    the wire protocol and, for ``simulate``, the simulated device and its load;
* ``node``        the lifecycle shell: transitions, /joint_commands -> loop -> /joint_states,
                  services;
* ``main``        the executable: executor, errors, exit;
* ``diagnostics`` what /diagnostics reports.

The loop itself, the watchdogs and limits are ROS-free (``canbus.loop``, ``core.driver``).
"""

from transparency_ros.ros.actuator_driver.main import main
from transparency_ros.ros.actuator_driver.node import ActuatorDriverNode
from transparency_ros.ros.actuator_driver.parameters import DESCRIPTION, NODE_NAME, PARAMETERS

__all__ = ["DESCRIPTION", "NODE_NAME", "PARAMETERS", "ActuatorDriverNode", "main"]
