"""Errors of the CAN layer. Each also inherits the matching built-in."""

from transparency_ros.core.errors import TransparencyError


class CanProtocolError(TransparencyError, ValueError):
    """A value cannot be encoded, or a frame cannot be decoded, under a protocol."""


class MalformedFrameError(CanProtocolError):
    """A frame of the right id whose length or content the protocol does not allow."""


class BusError(TransparencyError, OSError):
    """The CAN interface could not be opened, or failed while sending/receiving."""
