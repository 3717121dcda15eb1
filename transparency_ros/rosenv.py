"""Keep every ROS process this project starts on loopback and on a domain of its own.

Tests, the demo and benchmarks call :func:`local_ros_env` (or run this file, which prints a free
domain ID for the Makefile). It is stdlib-only on purpose: ``make`` runs it before the virtual
environment exists.

A domain counts as taken when its DDS discovery port (7400 + 250 * id, the RTPS well-known
multicast port) is bound on this machine, so two concurrent sessions do not share a domain.
"""

from __future__ import annotations

import os
import random
import sys
from collections.abc import Mapping

# Linux-safe domain IDs (0 is the default everybody uses; above 101 ports collide with the
# ephemeral range). We keep 1..100.
DOMAIN_MIN, DOMAIN_MAX = 1, 100
_PORT_BASE, _DOMAIN_GAIN = 7400, 250


def _bound_udp_ports() -> set[int]:
    ports: set[int] = set()
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            with open(table, encoding="ascii") as handle:
                next(handle, None)
                for line in handle:
                    local = line.split()[1]
                    ports.add(int(local.rsplit(":", 1)[1], 16))
        except (OSError, ValueError, IndexError):
            continue
    return ports


def pick_domain_id(rng: random.Random | None = None) -> int:
    """A random domain ID in 1..100 whose discovery port nobody on this machine has bound."""
    chooser = rng or random.SystemRandom()
    candidates = list(range(DOMAIN_MIN, DOMAIN_MAX + 1))
    chooser.shuffle(candidates)
    taken = _bound_udp_ports()
    for domain in candidates:
        if _PORT_BASE + _DOMAIN_GAIN * domain not in taken:
            return domain
    return candidates[0]


def local_ros_env(
    base: Mapping[str, str] | None = None, domain_id: int | None = None
) -> dict[str, str]:
    """A copy of ``base`` (default: os.environ) confined to loopback on its own domain."""
    env = dict(os.environ if base is None else base)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = str(pick_domain_id() if domain_id is None else domain_id)
    env.pop("ROS_STATIC_PEERS", None)
    return env


if __name__ == "__main__":
    print(pick_domain_id())
    sys.exit(0)
