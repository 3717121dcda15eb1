"""Find the package's installed data (config/*.yaml) in every supported layout.

Layouts, in the order they are tried:
1. ``$TRANSPARENCY_CONFIG_DIR`` when set (explicit override);
2. a source checkout or editable install: ``<repo>/config`` next to the package directory;
3. an install prefix (pip into a venv, or colcon's ``install/transparency_ros``):
   ``<prefix>/share/transparency_ros/config`` with the package in
   ``<prefix>/lib/pythonX.Y/site-packages/transparency_ros``;
4. every prefix on ``$AMENT_PREFIX_PATH`` (a sourced ROS workspace).
"""

from __future__ import annotations

import os
from pathlib import Path

from transparency_ros.core.errors import ConfigError

PACKAGE = "transparency_ros"
_PACKAGE_DIR = Path(__file__).resolve().parent.parent


def config_dir_candidates() -> list[Path]:
    """Every directory that may hold the package's config files, most specific first."""
    candidates: list[Path] = []
    override = os.environ.get("TRANSPARENCY_CONFIG_DIR")
    if override:
        candidates.append(Path(override))
    candidates.append(_PACKAGE_DIR.parent / "config")
    # <prefix>/lib/pythonX.Y/site-packages/transparency_ros -> parents[3] is <prefix>
    if len(_PACKAGE_DIR.parents) > 3:
        candidates.append(_PACKAGE_DIR.parents[3] / "share" / PACKAGE / "config")
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        candidates.append(Path(prefix) / "share" / PACKAGE / "config")
    return candidates


def config_file(name: str) -> Path:
    """Path of the installed config file ``name`` (e.g. ``actuators.yaml``)."""
    searched = config_dir_candidates()
    for directory in searched:
        path = directory / name
        if path.is_file():
            return path
    places = ", ".join(str(d) for d in searched)
    raise ConfigError(
        f"config file {name!r} not found; searched: {places}. "
        "Set TRANSPARENCY_CONFIG_DIR or reinstall the package."
    )
