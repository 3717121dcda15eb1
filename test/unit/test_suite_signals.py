"""The suite's own signal handling (test/conftest.py): a terminated run leaves no process behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # (a zombie is gone for this purpose: it runs nothing)
    stat = Path(f"/proc/{pid}/stat")
    return not (stat.exists() and stat.read_text().split(")")[-1].split()[0] == "Z")


def test_a_terminated_run_stops_the_processes_its_tests_started(tmp_path: Path) -> None:
    """SIGTERM to pytest runs the test's ``finally``: the child it started (a node, here a
    sleeper) is stopped there, not left running after the suite has gone."""
    pid_file = tmp_path / "child.pid"
    (tmp_path / "test_child.py").write_text(
        textwrap.dedent(
            f"""
            import subprocess, sys, time
            def test_starts_a_child():
                child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
                open({str(pid_file)!r}, "w").write(str(child.pid))
                try:
                    time.sleep(60)
                finally:
                    child.terminate()
                    child.wait(10)
            """
        )
    )
    run = subprocess.Popen(
        [sys.executable, "-m", "pytest", "-q", "-p", "test.conftest", "-p", "no:cacheprovider",
         str(tmp_path / "test_child.py")],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 60.0
        while not pid_file.exists() or not pid_file.read_text():
            assert run.poll() is None, run.communicate()[0]
            assert time.monotonic() < deadline, "the test never started its child"
            time.sleep(0.05)
        child = int(pid_file.read_text())
        assert _alive(child)
        run.send_signal(signal.SIGTERM)
        out, _ = run.communicate(timeout=30.0)
    finally:
        if run.poll() is None:
            run.kill()
            run.communicate()
    assert run.returncode != 0, out
    assert "KeyboardInterrupt" in out, out
    assert not _alive(child), f"pid {child} still running after the run ended:\n{out}"
