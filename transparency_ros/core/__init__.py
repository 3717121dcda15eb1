"""ROS-free functional core: configuration, physics, estimation, behavior.

Nothing in this package imports rclpy or ROS message packages (a test enforces it), and no
function here reads the clock: time is always passed in.
"""
