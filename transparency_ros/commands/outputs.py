"""Where commands write files the user named: checked before any work, never created."""

from __future__ import annotations

import os
from pathlib import Path

from transparency_ros.core.errors import ConfigError


def output_file(path: str, option: str) -> Path:
    """``path`` for a file an option names (``--plot x.png``): its directory must exist and be
    writable. A typo in a directory is refused in one line, not created (under / even)."""
    out = Path(path)
    parent = out.parent
    if not parent.is_dir():
        raise ConfigError(f"{option} {path}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise ConfigError(f"{option} {path}: directory {parent} is not writable")
    if out.is_dir():
        raise ConfigError(f"{option} {path}: is a directory")
    return out
