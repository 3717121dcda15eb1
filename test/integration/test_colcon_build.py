"""Route 2 of the README: a ROS workspace built with colcon.

Builds a copy of this package with colcon-core + colcon-ros (from PyPI) into tmp_path and checks
that everything `ros2 run transparency_ros <exe>` needs is installed where it looks: the
executables in lib/transparency_ros, the ament index marker, package.xml and config/.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
# the console_scripts of setup.py
EXECUTABLES = ["transparency", "actuator_driver", "contact_estimator", "feel_cage_behavior"]
IGNORE = shutil.ignore_patterns(
    ".venv*",
    ".git",
    "build",
    "install",
    "log",
    "demo_output",
    "__pycache__",
    "*.egg-info",
    ".*_cache",
    ".hypothesis",
)

pytestmark = pytest.mark.colcon


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    colcon = shutil.which("colcon", path=str(Path(sys.executable).parent))
    if colcon is None:
        pytest.fail("colcon is not installed next to the interpreter (requirements/dev.in)")
    ws = tmp_path_factory.mktemp("ws")
    shutil.copytree(REPO, ws / "src" / "transparency_ros", ignore=IGNORE)
    result = subprocess.run(
        [
            colcon,
            "--log-base",
            str(ws / "log"),
            "build",
            "--base-paths",
            str(ws / "src"),
            "--build-base",
            str(ws / "build"),
            "--install-base",
            str(ws / "install"),
            "--event-handlers",
            "console_direct-",
            "--packages-select",  # as the README and getting_started.md build it
            "transparency_ros",
        ],
        cwd=ws,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-4000:]
    return ws / "install" / "transparency_ros"


def test_executables_installed_where_ros2_run_looks(workspace: Path) -> None:
    lib = workspace / "lib" / "transparency_ros"
    for exe in EXECUTABLES:
        path = lib / exe
        assert path.is_file(), f"{exe} missing from {lib}: {sorted(os.listdir(lib))}"
        assert os.access(path, os.X_OK)


def test_ament_index_marker_and_share(workspace: Path) -> None:
    marker = (
        workspace / "share" / "ament_index" / "resource_index" / "packages" / "transparency_ros"
    )
    assert marker.is_file()
    share = workspace / "share" / "transparency_ros"
    assert (share / "package.xml").is_file()
    assert {p.name for p in (share / "config").glob("*.yaml")} >= {
        "actuators.yaml",
        "drop_test.yaml",
    }


def test_ament_index_resolves_the_package(workspace: Path) -> None:
    """What `ros2 run` does: find the prefix through the ament index, then lib/<package>/<exe>."""
    code = (
        "from ament_index_python.packages import get_package_prefix;"
        "print(get_package_prefix('transparency_ros'))"
    )
    env = {**os.environ, "AMENT_PREFIX_PATH": str(workspace)}
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert Path(out.stdout.strip()) == workspace


def test_installed_executable_runs_from_the_install_space(workspace: Path, tmp_path: Path) -> None:
    site = next(workspace.glob("lib/python3*/site-packages"))
    env = {key: value for key, value in os.environ.items() if key != "TRANSPARENCY_CONFIG_DIR"}
    env["PYTHONPATH"] = str(site)
    exe = workspace / "lib" / "transparency_ros" / "transparency"
    out = subprocess.run(
        [str(exe), "model", "--actuator", "EC60", "--energy", "1", "--json"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    assert '"detected": true' in out.stdout
    probe = "import transparency_ros.core.resources as r; print(r.config_file('actuators.yaml'))"
    where = subprocess.run(
        [sys.executable, "-c", probe],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    assert (
        Path(where.stdout.strip())
        == workspace / "share" / "transparency_ros" / "config" / "actuators.yaml"
    )
