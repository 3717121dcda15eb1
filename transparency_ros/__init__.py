"""transparency_ros: proprioceptive contact detection with transparent actuators.

Layout (see README "Architecture"): ``core`` (ROS-free physics, config, estimation),
``analysis`` (curves, plots, evaluation), ``commands`` (the ``transparency`` CLI's subcommands).
Only ``transparency_ros.ros`` may import rclpy or message packages.
"""

__version__ = "0.1.0"
