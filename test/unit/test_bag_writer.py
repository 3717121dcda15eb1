"""The bag writer: MCAP with embedded schemas, custom_data, atomic, never half-written."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from transparency_ros.bag.errors import BagWriteError
from transparency_ros.bag.keys import INTERRUPTED_KEY
from transparency_ros.bag.reader import open_bag, scalar_series
from transparency_ros.bag.writer import (
    BagWriter,
    check_writable,
    message_types,
    time_msg,
)
from transparency_ros.core.interrupts import (
    Terminated,
    deferred_interrupts,
    terminate_like_interrupt,
)


def point(z: float, ns: int) -> object:
    t = message_types()
    return t["geometry_msgs/msg/PointStamped"](
        header=t["std_msgs/msg/Header"](
            stamp=time_msg(ns),
            frame_id="rail",
        ),
        point=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=z),
    )


def write(path: Path, n: int = 5) -> None:
    with BagWriter(path, {"transparency.trial": "drop_test"}) as bag:
        bag.add("/shuttle/height", "geometry_msgs/msg/PointStamped")
        for i in range(n):
            ns = 1_000_000_000 + i * 100_000
            bag.write_message("/shuttle/height", ns, point(0.1 * i, ns))


def test_round_trip_with_custom_data_and_the_ros2_mcap_profile(tmp_path: Path) -> None:
    write(tmp_path / "bag")
    with open_bag(tmp_path / "bag") as bag:
        assert bag.custom_data == {"transparency.trial": "drop_test"}
        data = scalar_series(bag, "/shuttle/height", "geometry_msgs/msg/PointStamped", "point.z")
    assert data.value.tolist() == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    assert np.diff(data.stamp_ns).tolist() == [100_000] * 4
    (mcap_file,) = (tmp_path / "bag").glob("*.mcap")
    with mcap_file.open("rb") as handle:  # what Foxglove / ros2 bag read
        reader = make_reader(handle)
        assert reader.get_header().profile == "ros2"
        schemas = reader.get_summary().schemas.values()
        assert [(s.name, s.encoding) for s in schemas] == [
            ("geometry_msgs/msg/PointStamped", "ros2msg")
        ]
        assert all(s.data for s in schemas)  # definitions embedded
    assert not (tmp_path / "bag.partial").exists()


def _interrupted_trial(path: Path, error: BaseException) -> None:
    with BagWriter(path) as bag:
        bag.add("/shuttle/height", "geometry_msgs/msg/PointStamped")
        bag.write_message("/shuttle/height", 1, point(0.5, 1))
        raise error


def test_a_failure_leaves_no_bag_and_ctrl_c_keeps_what_was_written(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError):
        _interrupted_trial(tmp_path / "failed", RuntimeError("trial failed"))
    assert not (tmp_path / "failed").exists() and not (tmp_path / "failed.partial").exists()
    with pytest.raises(KeyboardInterrupt):
        _interrupted_trial(tmp_path / "interrupted", KeyboardInterrupt())
    with open_bag(tmp_path / "interrupted") as kept:
        assert [m.point.z for _, _, m in kept.messages(["/shuttle/height"])] == [0.5]
        assert kept.custom_data[INTERRUPTED_KEY] == "SIGINT"  # the evaluation skips it


def _write_until_killed(path: Path) -> None:
    with BagWriter(path) as bag:
        bag.add("/shuttle/height", "geometry_msgs/msg/PointStamped")
        for i in range(100):
            bag.write_message("/shuttle/height", i + 1, point(0.01 * i, i + 1))
        os.kill(os.getpid(), signal.SIGTERM)  # a real signal, handled in this thread
        time.sleep(5.0)  # interrupted


def test_sigterm_closes_the_bag_like_ctrl_c(tmp_path: Path) -> None:
    previous = signal.getsignal(signal.SIGTERM)
    terminate_like_interrupt()
    try:
        with pytest.raises(Terminated):
            _write_until_killed(tmp_path / "bag")
    finally:
        signal.signal(signal.SIGTERM, previous)
    with open_bag(tmp_path / "bag") as kept:
        assert kept.custom_data[INTERRUPTED_KEY] == "SIGTERM"
        assert kept.topics["/shuttle/height"].count == 100
    assert not (tmp_path / "bag.partial").exists()


def _signal_inside(caught: list[str]) -> None:
    with deferred_interrupts():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)
        caught.append("still running")  # not interrupted inside the block


def test_a_signal_during_the_close_waits_for_it(sigint_raises: None) -> None:
    caught: list[str] = []
    with pytest.raises(KeyboardInterrupt):
        _signal_inside(caught)
    assert caught == ["still running"]


FULL_DISK = """
import os, resource, signal, sys
from pathlib import Path
from transparency_ros.bag.errors import BagWriteError
from transparency_ros.bag.writer import BagWriter
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes past the limit fail with EFBIG
resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))  # as a full disk would
try:
    with BagWriter(Path(sys.argv[1])) as bag:
        bag.add("/raw", "std_msgs/msg/String")
        for i in range(200):
            payload = os.urandom(10_000)  # incompressible: the chunks reach the file
            cdr = bytes([0, 1, 0, 0]) + len(payload).to_bytes(4, "little") + payload
            bag.write("/raw", i, cdr)
except BagWriteError as err:
    print("ERROR", err)
"""


def test_a_full_disk_is_a_clear_error_and_leaves_no_half_bag(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-c", FULL_DISK, str(tmp_path / "bag")],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("ERROR cannot write /raw into bag "), done.stdout
    assert "File too large" in done.stdout  # the OS's reason is passed on
    assert not (tmp_path / "bag").exists() and not (tmp_path / "bag.partial").exists()


def test_existing_bags_and_unwritable_directories_are_refused(tmp_path: Path) -> None:
    write(tmp_path / "bag")
    with pytest.raises(BagWriteError, match="exists already"):
        BagWriter(tmp_path / "bag")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):  # root ignores permissions: use a path under a file
            blocker = tmp_path / "a_file"
            blocker.write_text("")
            with pytest.raises(BagWriteError, match="cannot create bag directory"):
                check_writable(blocker / "bags")
        else:
            with pytest.raises(BagWriteError, match="not writable"):
                check_writable(locked)
    finally:
        locked.chmod(0o700)
    with pytest.raises(BagWriteError, match="MB free"):
        check_writable(tmp_path, min_free_bytes=1 << 62)


def test_a_finished_bag_names_its_file_after_itself(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "trial", {"k": "v"}) as bag:
        bag.add("/x", "std_msgs/msg/String")
    assert sorted(p.name for p in (tmp_path / "trial").iterdir()) == ["metadata.yaml", "trial.mcap"]
    assert "partial" not in (tmp_path / "trial" / "metadata.yaml").read_text()
    with open_bag(tmp_path / "trial") as opened:
        assert opened.custom_data["k"] == "v"
