"""Subcommands of the ``transparency`` command (see :mod:`transparency_ros.cli`)."""
