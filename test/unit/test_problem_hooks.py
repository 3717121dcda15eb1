"""The optional hooks of a discrepancy Problem: declared once (problem.Hooks), read through
problem.hook, which falls back to the declared default and refuses a name not declared."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from transparency_ros.analysis.discrepancy.problem import SIGNIFICANT, Hooks, hook


def test_a_problem_s_own_hook_wins_over_the_default() -> None:
    problem = SimpleNamespace(unit="N", pairs=False)
    assert hook(problem, "unit") == "N"
    assert hook(problem, "pairs") is False
    assert hook(problem, "channel") == Hooks.channel == "simulation"


def test_a_default_method_is_bound_to_the_problem() -> None:
    """structure_left by default compares the error with the problem's own floor."""
    problem = SimpleNamespace(noise_floor=lambda: 0.01)
    left = hook(problem, "structure_left")
    assert left(np.full(10, 0.99 * SIGNIFICANT * 0.01)) is False
    assert left(np.full(10, 1.01 * SIGNIFICANT * 0.01)) is True
    assert hook(problem, "accepts")([], []) is True
    assert hook(problem, "leftover_scope")(np.zeros(3)) is None


def test_an_undeclared_hook_is_refused() -> None:
    """A misspelt hook must not fall silently to a default."""
    with pytest.raises(AttributeError, match="leftover_scop"):
        hook(SimpleNamespace(leftover_scop=None), "leftover_scop")


def test_every_hook_the_loop_reads_is_declared() -> None:
    """Each name read through hook() in the package is one Hooks declares."""
    import re  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    import transparency_ros  # noqa: PLC0415

    root = Path(transparency_ros.__file__).parent
    names = {
        m
        for f in root.rglob("*.py")
        for m in re.findall(r'hook\((?:self\.)?problem, "(\w+)"\)', f.read_text())
    }
    assert len(names) >= 15
    assert names <= set(vars(Hooks))
