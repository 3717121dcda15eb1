"""Keep every ROS process this project starts on loopback and on a domain of its own.

Tests, the demo and benchmarks call :func:`local_ros_env` or :func:`pick_domain_id` (or run this
file, which prints a free domain ID for the Makefile). It is stdlib-only on purpose: ``make``
runs it before the virtual environment exists.

A domain is free when both hold:

- no process on this machine has bound a UDP port of the domain's range (RTPS puts domain d on
  ports 7400 + 250 d .. 7400 + 250 d + 249: discovery and user traffic, multicast and unicast;
  with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` only the unicast ones, 7410 + 250 d + 2 i and
  up, are bound, so the whole range is looked at, not the multicast port alone);
- no process of this project holds the domain's lock (an ``flock`` on a file per domain in a
  directory of the user's own in the temp directory). A picked domain is held until
  :func:`release_domain_id` or the process's end (the kernel drops the lock of a dead process),
  so two test suites, demos or benchmarks started at once never share one, even between the pick
  and the moment their first participant binds its ports.
"""

from __future__ import annotations

import errno
import fcntl
import os
import random
import sys
import tempfile
from collections.abc import Mapping

# Linux-safe domain IDs (0 is the default everybody uses; above 101 ports collide with the
# ephemeral range). We keep 1..100.
DOMAIN_MIN, DOMAIN_MAX = 1, 100
_PORT_BASE, _DOMAIN_GAIN = 7400, 250
LOCK_DIR = os.path.join(tempfile.gettempdir(), f"transparency_ros-{os.getuid()}-domains")

_held: dict[int, int] = {}  # domain -> the file descriptor holding its lock (-1: no lock made)


class NoFreeDomainError(RuntimeError):
    """Every domain in DOMAIN_MIN..DOMAIN_MAX is in use on this machine."""


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


def domain_ports(domain: int) -> range:
    """The UDP ports RTPS may use for ``domain`` (every participant, every kind of traffic)."""
    return range(_PORT_BASE + _DOMAIN_GAIN * domain, _PORT_BASE + _DOMAIN_GAIN * (domain + 1))


def _lock(domain: int, lock_dir: str) -> int | None:
    """The descriptor holding ``domain``'s lock; None when another process holds it.

    Where no lock can be made (a read-only temp directory), -1: the port check alone decides."""
    try:
        os.makedirs(lock_dir, mode=0o700, exist_ok=True)
        fd = os.open(
            os.path.join(lock_dir, f"{domain}.lock"), os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600
        )
    except OSError:
        return -1
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as err:
        os.close(fd)
        if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            return None
        return -1
    return fd


def pick_domain_id(rng: random.Random | None = None, *, lock_dir: str | None = None) -> int:
    """A random domain ID in 1..100 that no process on this machine uses, held by this process
    until :func:`release_domain_id` (or its end). NoFreeDomainError when all are in use."""
    chooser = rng or random.SystemRandom()
    lock_dir = LOCK_DIR if lock_dir is None else lock_dir
    candidates = list(range(DOMAIN_MIN, DOMAIN_MAX + 1))
    chooser.shuffle(candidates)
    taken = _bound_udp_ports()
    for domain in candidates:
        if domain in _held or not taken.isdisjoint(domain_ports(domain)):
            continue
        fd = _lock(domain, lock_dir)
        if fd is None:
            continue
        _held[domain] = fd  # (-1: not locked, still never picked twice by this process)
        return domain
    raise NoFreeDomainError(
        f"no free ROS domain in {DOMAIN_MIN}..{DOMAIN_MAX} on this machine (UDP ports of each "
        f"bound, or its lock in {lock_dir} held): stop other ROS processes, or give one yourself "
        "(ROS_DOMAIN_ID; for the test suite TRANSPARENCY_TEST_DOMAIN_ID)"
    )


def release_domain_id(domain: int) -> None:
    """Let other processes pick ``domain`` again (a domain this process does not hold: no-op)."""
    fd = _held.pop(domain, None)
    if fd is not None and fd >= 0:
        os.close(fd)  # closing the last descriptor drops the flock


def held_domain_ids() -> list[int]:
    """The domains this process holds, in the order picked."""
    return list(_held)


def local_ros_env(
    base: Mapping[str, str] | None = None, domain_id: int | None = None
) -> dict[str, str]:
    """A copy of ``base`` (default: os.environ) confined to loopback on its own domain (picked and
    held by :func:`pick_domain_id` unless ``domain_id`` is given)."""
    env = dict(os.environ if base is None else base)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = str(pick_domain_id() if domain_id is None else domain_id)
    env.pop("ROS_STATIC_PEERS", None)
    return env


if __name__ == "__main__":
    # the lock goes with this process: the port check and a random draw keep ``make``'s pick
    # apart from others; the processes it starts pick and hold their own where it matters
    try:
        print(pick_domain_id())
    except NoFreeDomainError as err:
        print(f"rosenv: error: {err}", file=sys.stderr)
        sys.exit(1)
