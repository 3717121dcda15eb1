"""The discovery loop's second search (:mod:`discover`): in two places the loop chooses between
fits that explain the held-out data alike by a preference, not by the data (a shown rebound
gives way to a hub spring, ``Discoverer._rival_instead``; in ``steps.choose`` a Coulomb drift
yields to an offset, a rebound to a spring: ``yields_to``). The loop counts those choices
(:func:`other_way`); where it met one, it is run once more taking the other fit at the first
(:func:`other_branch`), and the model that explains the held-out recordings better is reported.
A tie broken one way may lead where nothing more is named (zoo_13480: a hub spring taken for
the shown rebound, alike, left 6 times the noise floor; the rebound taken, the backlash hidden
beside it was named and the model left 1.7 times the floor)."""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING

from transparency_ros.analysis.discrepancy.fitting import CRITERION, aic, rmse
from transparency_ros.analysis.discrepancy.model import FloatArray
from transparency_ros.analysis.discrepancy.steps import ALIKE, Step, total

if TYPE_CHECKING:
    from transparency_ros.analysis.discrepancy.discover import Discoverer
    from transparency_ros.analysis.discrepancy.findings import Report


def other_way(loop: Discoverer, behind: Step) -> bool:
    """At a choice between fits alike made by an effect's yielding (``behind``: the step of
    the effect put behind), whether ``loop`` takes ``behind`` instead; the first such choice
    is kept in the loop (``Discoverer.run`` searches again from it)."""
    count, loop._ties = loop._ties, loop._ties + 1
    if loop._take is None and loop._tie is None:
        loop._tie = (count, "+".join(a.name for a in behind.added))
    return loop._take == count


def taken(step: Step, other: Step) -> Step:
    """``other``, alike with ``step`` and taken in its place: the others alike its own."""
    other.alike = [c for c in [step, *step.alike] if c is not other]
    other.alternatives = ["+".join(a.name for a in c.added) for c in other.alike]
    return other


def other_branch(
    loop: Discoverer,
    report: Report,
    err: FloatArray,
    params: list[FloatArray],
    tie: tuple[int, str],
) -> Report:
    """``report`` (its model's held-out error ``err`` and parameters), or the report of the
    search that takes the step ``tie`` names at that choice, where that model explains the
    held-out recordings better (beyond ``ALIKE``, and by the information criterion by
    ``CRITERION``); the kept report says which in a note."""
    # (the same candidates are searched again, and a scan keeps what it chose in its effect,
    # a cogging's period: the first model keeps its own copies)
    report.fitted = [(copy.copy(e), p) for e, p in report.fitted]
    # (the loop's own class: a subclass that logs its steps, benchmarks/share_calibration)
    other = type(loop)(loop.problem, min_improvement=loop.min_improvement, progress=loop.progress)
    other.keep_improvement = loop.keep_improvement
    other._take, names = tie
    loop.progress(f"searching again, taking {names} where the search took another alike")
    branch, err_b, params_b = other._run_once()
    before, after = rmse(err), rmse(err_b)
    fewer = aic(err_b, total(params_b)) < aic(err, total(params)) - CRITERION
    better = after * ALIKE < before and fewer
    kept, outcome = (branch, "reported") if better else (report, "not better: not reported")
    kept.notes.append(
        f"{names} explained the recordings alike with the effect named in its place; the "
        f"search taking {names} there instead reaches a model of held-out RMSE {after:.4g} "
        f"against {before:.4g}: {outcome}"
    )
    return kept
