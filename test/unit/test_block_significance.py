"""benchmarks/block_significance.py: the blocks' t its figures in docs/robots.md rest on."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import block_significance  # noqa: E402


class _Problem:
    """Two joints; one held-out run of ``samples`` compared points; a step acts on the joints
    in ``scope`` (None: both)."""

    def __init__(self, samples: int, scope: list[int] | None) -> None:
        self.model = SimpleNamespace(dof=2)
        self.held_runs = [SimpleNamespace(t=np.zeros(samples))]
        self.scope = scope

    def sensor_scope(
        self, added: list[Any], after: bool, modelled: Any = ()
    ) -> tuple[np.ndarray, float] | None:
        if self.scope is None:
            return None
        return np.isin(np.tile(np.arange(2), self.held_runs[0].t.size), self.scope), 1.0


def test_a_consistent_gain_has_a_large_t_and_a_reshuffle_of_noise_does_not() -> None:
    rng = np.random.default_rng(5)
    n = 20 * block_significance.BLOCK
    problem = _Problem(n, [0])
    before = rng.normal(size=2 * n)
    after = before.copy()
    after[0::2] *= np.sqrt(0.9)  # a tenth of joint 0's variance removed everywhere
    t = block_significance.joint_t(
        problem, SimpleNamespace(added=[], err=after), SimpleNamespace(err=before)
    )
    assert len(t) == 1 and t[0] > 10
    noise = before.copy()
    noise[0::2] = rng.normal(size=n)
    t = block_significance.joint_t(
        problem, SimpleNamespace(added=[], err=noise), SimpleNamespace(err=before)
    )
    assert abs(t[0]) < 4


def test_each_joint_a_step_acts_on_gets_its_own_t() -> None:
    rng = np.random.default_rng(6)
    n = 20 * block_significance.BLOCK
    problem = _Problem(n, None)
    before = rng.normal(size=2 * n)
    after = before.copy()
    after[0::2] *= np.sqrt(0.8)
    after[1::2] *= np.sqrt(1.2)  # joint 1 made worse
    t = block_significance.joint_t(
        problem, SimpleNamespace(added=[], err=after), SimpleNamespace(err=before)
    )
    assert t[0] > 10 and t[1] < -block_significance.WORSE
