"""Architecture rules: only transparency_ros.ros may import rclpy or ROS message packages."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import transparency_ros

PACKAGE_DIR = Path(transparency_ros.__file__).parent
ROS_MODULES = {
    "rclpy",
    "sensor_msgs",
    "std_msgs",
    "geometry_msgs",
    "diagnostic_msgs",
    "lifecycle_msgs",
    "builtin_interfaces",
    "rcl_interfaces",
    "launch",
    "launch_ros",
}


def _imported_roots(path: Path) -> set[str]:
    roots: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            roots.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            roots.add(node.module.split(".")[0])
    return roots


def test_only_the_ros_shell_imports_ros() -> None:
    offenders = {}
    for path in PACKAGE_DIR.rglob("*.py"):
        relative = path.relative_to(PACKAGE_DIR)
        if relative.parts[0] == "ros":
            continue
        bad = _imported_roots(path) & ROS_MODULES
        if bad:
            offenders[str(relative)] = sorted(bad)
    assert offenders == {}


def test_importing_core_and_cli_loads_no_ros() -> None:
    modules = sorted(
        "transparency_ros." + ".".join(p.relative_to(PACKAGE_DIR).with_suffix("").parts)
        for p in PACKAGE_DIR.rglob("*.py")
        if p.relative_to(PACKAGE_DIR).parts[0] != "ros" and p.name != "__main__.py"
    )
    code = (
        "import importlib, sys\n"
        f"for m in {modules!r}: importlib.import_module(m)\n"
        f"print(sorted(r for r in {sorted(ROS_MODULES)!r} if r in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    assert len(modules) >= 8
