"""Errors of the bag layer; each names the bag (and topic) it is about."""

from __future__ import annotations

from transparency_ros.core.errors import TransparencyError


class BagError(TransparencyError):
    """A bag that cannot be read or written as asked."""


class BagWriteError(BagError, OSError):
    """The bag could not be written (unwritable directory, full disk, existing bag)."""


class BagReadError(BagError, ValueError):
    """The bag is missing, damaged, or lacks what the caller needs."""
