"""CAN side of the driver, ROS-free.

* ``mit``, ``odrive``, ``moteus_fd``: pure encode/decode of the three wire protocols, in each
  protocol's native units;
* ``protocol``: adapters that put all three behind one actuator interface in SI output-side units;
* ``client``: an actuator client on a python-can bus (I/O, counters);
* ``sim_device``: a simulated actuator that answers on a python-can bus exactly as the firmware
  does, driven by :mod:`transparency_ros.core.actuator_physics`;
* ``sim_robot``: several simulated actuators sharing a bus, several buses in one thread;
* ``loop``, ``multi``: the control loop for one motor and for a robot's motors.

Named ``canbus`` rather than ``can`` so that ``import can`` always means python-can.
"""
