"""Session-wide test setup.

Every ROS process a test starts (in-process rclpy contexts and subprocesses alike) inherits this
environment: discovery confined to loopback and a domain ID chosen for this session only, never
the caller's (a developer's shell may point at a live robot). It is set at import time, before
any test module can import rclpy. Set TRANSPARENCY_TEST_DOMAIN_ID to force a domain.
"""

from __future__ import annotations

import os

from transparency_ros.rosenv import local_ros_env

_forced = os.environ.get("TRANSPARENCY_TEST_DOMAIN_ID")
os.environ.update(local_ros_env(domain_id=int(_forced) if _forced else None))
os.environ.setdefault("MPLBACKEND", "Agg")
