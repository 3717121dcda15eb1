"""Domain choice (transparency_ros/rosenv.py): two processes of this project never share a ROS
domain, and a domain whose ports anybody has bound is left alone.

Two test suites started at once once picked the same domain: a bag replay test of one counted
the other's messages (366 joint states for 324 replayed). The pick then looked at one port per
domain (7400 + 250 d, multicast discovery), which a participant confined to loopback never
binds, and nothing was held between the pick and the participant's start."""

from __future__ import annotations

import os
import random
import socket
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest

from transparency_ros import rosenv
from transparency_ros.rosenv import (
    DOMAIN_MAX,
    DOMAIN_MIN,
    NoFreeDomainError,
    domain_ports,
    held_domain_ids,
    pick_domain_id,
    release_domain_id,
)

ALL = range(DOMAIN_MIN, DOMAIN_MAX + 1)


def _holder(lock_dir: Path, count: int) -> subprocess.Popen[str]:
    """Another process that picks ``count`` domains, prints them and holds them until stdin ends
    (the locks alone decide there too: ROS processes of this machine bind ports meanwhile)."""
    code = textwrap.dedent(f"""
        import sys
        from transparency_ros import rosenv
        from transparency_ros.rosenv import pick_domain_id
        rosenv._bound_udp_ports = set
        print(*(pick_domain_id(lock_dir={str(lock_dir)!r}) for _ in range({count})), flush=True)
        sys.stdin.read()
    """)
    return subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)  # fmt: skip


def _picked_by(proc: subprocess.Popen[str]) -> set[int]:
    assert proc.stdout is not None
    return {int(word) for word in proc.stdout.readline().split()}


def _release_all_of(proc: subprocess.Popen[str]) -> None:
    assert proc.stdin is not None
    proc.stdin.close()
    proc.wait(timeout=30)


@pytest.fixture
def no_ports_bound(monkeypatch: pytest.MonkeyPatch) -> None:
    """Other tests of this session may run ROS participants: only the locks decide here."""
    monkeypatch.setattr(rosenv, "_bound_udp_ports", set)


@pytest.fixture
def already_held(tmp_path: Path) -> Iterator[set[int]]:
    """The domains this process holds already (the session's, test/conftest.py), locked in
    ``tmp_path`` too: another process using that lock directory leaves them alone, as this one
    does."""
    held = set(held_domain_ids())
    fds = [rosenv._lock(domain, str(tmp_path)) for domain in held]
    yield held
    for fd in fds:
        if fd is not None and fd >= 0:
            os.close(fd)


def test_a_domain_held_by_another_process_is_never_picked(
    tmp_path: Path, no_ports_bound: None, already_held: set[int]
) -> None:
    other = _holder(tmp_path, len(ALL) - len(already_held) - 1)
    try:
        theirs = _picked_by(other)
        free = set(ALL) - theirs - already_held
        assert len(free) == 1
        mine = pick_domain_id(random.Random(0), lock_dir=str(tmp_path))
        assert {mine} == free
        release_domain_id(mine)
    finally:
        _release_all_of(other)


def test_all_domains_held_is_a_clear_error_and_a_dead_holder_frees_them(
    tmp_path: Path, no_ports_bound: None
) -> None:
    other = _holder(tmp_path, len(ALL))
    try:
        assert _picked_by(other) == set(ALL)
        with pytest.raises(NoFreeDomainError, match=r"no free ROS domain in 1\.\.100"):
            pick_domain_id(lock_dir=str(tmp_path))
    finally:
        _release_all_of(other)
    # the kernel dropped the dead process's locks
    mine = pick_domain_id(lock_dir=str(tmp_path))
    assert mine in ALL
    release_domain_id(mine)


def test_a_released_domain_can_be_picked_by_another_process(
    tmp_path: Path, no_ports_bound: None, already_held: set[int]
) -> None:
    mine: list[int] = []
    try:
        while len(mine) + len(already_held) < len(ALL):
            mine.append(pick_domain_id(lock_dir=str(tmp_path)))
        assert len(set(mine)) == len(mine) and set(mine) <= set(held_domain_ids())
        release_domain_id(mine[0])
        other = _holder(tmp_path, 1)
        try:
            assert _picked_by(other) == {mine[0]}
        finally:
            _release_all_of(other)
    finally:
        for domain in mine[1:]:
            release_domain_id(domain)
    assert not set(mine) & set(held_domain_ids())


def test_where_no_lock_can_be_made_a_pick_is_still_held_by_this_process(
    tmp_path: Path, no_ports_bound: None, already_held: set[int]
) -> None:
    """A lock directory that cannot be made (here under a plain file; a read-only temp
    directory alike): the port check alone keeps other processes off, and this process still
    never picks one domain twice until it lets it go."""
    (tmp_path / "a_file").write_text("")
    nowhere = str(tmp_path / "a_file" / "domains")
    mine: list[int] = []
    try:
        while len(mine) + len(already_held) < len(ALL):
            mine.append(pick_domain_id(lock_dir=nowhere))
        assert len(set(mine)) == len(mine) and not set(mine) & already_held
        with pytest.raises(NoFreeDomainError, match="TRANSPARENCY_TEST_DOMAIN_ID"):
            pick_domain_id(lock_dir=nowhere)
        release_domain_id(mine[0])
        assert pick_domain_id(lock_dir=nowhere) == mine[0]
    finally:
        for domain in mine:
            release_domain_id(domain)
    assert not set(mine) & set(held_domain_ids())


def test_processes_picking_at_once_get_different_domains(
    tmp_path: Path, no_ports_bound: None
) -> None:
    holders = [_holder(tmp_path, 12) for _ in range(6)]
    try:
        picked = [_picked_by(proc) for proc in holders]
    finally:
        for proc in holders:
            _release_all_of(proc)
    assert all(len(domains) == 12 for domains in picked)
    assert len(set().union(*picked)) == 6 * 12  # pairwise disjoint


class _First(random.Random):
    """A shuffle that puts one domain first (the one the test wants looked at first)."""

    def __init__(self, domain: int) -> None:
        super().__init__(0)
        self.domain = domain

    def shuffle(self, x: list[int]) -> None:  # type: ignore[override]
        x.sort(key=lambda d: d != self.domain)


def test_any_bound_port_of_a_domain_takes_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST a participant binds 7410 + 250 d and up,
    never the multicast port 7400 + 250 d: any port of the range counts."""
    monkeypatch.setattr(rosenv, "_bound_udp_ports", lambda: {domain_ports(37).start + 10})
    mine = pick_domain_id(_First(37), lock_dir=str(tmp_path))
    release_domain_id(mine)
    assert mine != 37
    monkeypatch.undo()
    # a real socket of this process on a unicast port of a domain
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for domain in ALL:
            try:
                sock.bind(("127.0.0.1", domain_ports(domain).start + 11))
                break
            except OSError:
                continue
        mine = pick_domain_id(_First(domain), lock_dir=str(tmp_path))
        release_domain_id(mine)
        assert mine != domain


def test_the_makefile_form_prints_one_domain() -> None:
    script = Path(rosenv.__file__)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=30, check=True)  # fmt: skip
    assert int(done.stdout) in ALL and not done.stderr
