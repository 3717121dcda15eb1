"""The ROS 2 shell: the only package that imports rclpy and message types.

Nodes convert messages and parameters to and from the ROS-free core, and nothing else.
"""
