"""The loop: simulate -> residual -> locate -> explain -> model -> select, until nothing is left.

The loop is the same for every kind of recording; a *problem* (``problem.Problem``) says how to
simulate its trials and compare them: ``torque_driven.TorqueDrivenProblem`` for 1-DoF
torque-driven recordings, ``drop.DropProblem`` for drop tests. Fitting is in ``fitting``, what
is reported (findings, where, unexplained) in ``findings``.

Trials are split into fitting and held-out sets (whole trials, never samples of one trial). Each
round fits every remaining candidate effect (its own parameters, bounded least squares on the
simulation error of the fitting trials; then all parameters found so far together with it),
scores it on the held-out trials, and keeps the best only if it removes at least
``min_improvement`` of the held-out error above the noise floor (what sensor noise alone would
cause; for an effect of one sensor's readings, of that sensor's error above its own floor), at
least a tenth of the floor in absolute terms, the held-out information criterion
(n log(RSS/n) + 2k) improves by more than 10, and its fit is meaningful (a wave whose period
stands out of its scan is named without the share: ``steps.prominent_wave``). When no single
candidate passes and a phase is left unexplained, candidates are fitted two at a time (two
missing effects may each explain too little alone; ``pairs``), only with it where one
candidate explains it at values it cannot mean (held at a bound). A kept effect gets
its parameters with 95 % confidence intervals (from the fit's Jacobian), where it acted (the
motion phase whose residual it reduced most, and the trial and time window of the largest
reduction) and the evidence.
Effects whose size the recording declares (the shuttle's weight: ``declared``) are not searched
for: each is added, nothing fitted, where it improves the held-out fit, before the search and
after each finding. A 95 % interval holding an effect's null value (``null``) names nothing;
intervals are widened by the problem's ``model_error_share`` of the value at the end. A
problem with a second channel (``force_view``: a drop test's load cell while the shuttle rides
the arm) has the candidates not named searched once more there, the effects found held. What
is left after the search (decisions taken again on the final model first, ``revisit``: a
shown effect against its rival, each searched effect tried again without it, an effect
against its variants of fewer parameters, a drift's Coulomb part against an offset) is checked
for structure (phase RMS against the noise floor, its dominant frequency, how much of it the
state explains, the closest candidate) and reported as ``unexplained``, never forced onto a
label. Where the loop chose between two fits alike only because one effect yields to the other
(a shown rebound to a hub spring, a Coulomb drift to an offset), it is run again taking the
other there, and the model that explains the held-out recordings better is reported."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

from transparency_ros.analysis.discrepancy.branch import other_branch, other_way, taken
from transparency_ros.analysis.discrepancy.effects import Effect
from transparency_ros.analysis.discrepancy.findings import (
    Report,
    finding,
    leftover,
    unexplained_phases,
    update_findings,
    widen,
)
from transparency_ros.analysis.discrepancy.fitting import (
    CRITERION,
    aic,
    fit_candidate,
    interval,
    parameter_count,
    refit,
    rmse,
)
from transparency_ros.analysis.discrepancy.model import FloatArray, NominalModel, Trial
from transparency_ros.analysis.discrepancy.pairs import (
    beyond_range,
    fitted_pairs,
    out_of_range,
    with_declared,
)
from transparency_ros.analysis.discrepancy.problem import SIGNIFICANT, Problem, hook
from transparency_ros.analysis.discrepancy.revisit import (
    friction_given_away,
    rivals_again,
    still_needed,
    told_from_nothing,
    variants_again,
)
from transparency_ros.analysis.discrepancy.steps import (
    ALIKE,
    WAVE_CYCLES,  # noqa: F401 - the wave's thresholds, read here by tests and benchmarks
    WAVE_FALSE_ALARM,  # noqa: F401
    Base,
    Step,
    choose,
    driven_to_bound,
    not_named,
    null_inside,
    same,
    scan_facts,
    share_needed,
    share_removed,
    short_of_floor,
    stood_in,
    total,
)
from transparency_ros.analysis.discrepancy.torque_driven import TorqueDrivenProblem
from transparency_ros.core.errors import ModelError


class Discoverer:
    """The loop on one :class:`Problem`: :meth:`run` names effects one round at a time (pairs
    when no single effect explains enough) and reports what is left."""

    # the share each effect must still remove on the final model (revisit.still_needed;
    # None: min_improvement); benchmarks/robot_zoo.py compares rules with it. (A class
    # default: test_revisit makes its loop without __init__.)
    keep_improvement: float | None = None
    # the choices between fits alike made by an effect's yielding to another (a rebound to a
    # hub spring, a Coulomb drift to an offset), counted as they come; the first (its count,
    # the effect put behind) and the one this loop makes the other way (run). (Class
    # defaults too: tests make loops without __init__.)
    _ties = 0
    _tie: tuple[int, str] | None = None
    _take: int | None = None

    def __init__(
        self,
        problem: Problem,
        *,
        min_improvement: float | None = None,
        progress: Callable[[str], None] = lambda _t: None,
    ) -> None:
        self.problem = problem
        self.min_improvement = (
            problem.min_improvement if min_improvement is None else min_improvement
        )
        self.progress = progress
        # the last refused step of each shown effect (by id): what the report's note on a
        # shown effect not named says
        self._refused: dict[int, Step] = {}
        # the effects the search named alone (by id): revisit.still_needed tries them again
        self._searched: set[int] = set()

    def run(self) -> Report:
        """The loop; where it chose between two fits alike only because one effect yields to
        the other (a shown rebound to a hub spring, ``_rival_instead``; a Coulomb drift to an
        offset, ``yields_to`` in ``choose``), it is run again taking the other there (the
        first such choice), and the model that explains the held-out recordings better
        (beyond ``ALIKE``, and by the information criterion by 10) is reported
        (``branch``)."""
        started = time.perf_counter()
        report, err, params = self._run_once()
        if self._tie is not None and self._take is None:
            report = other_branch(self, report, err, params, self._tie)
            report.seconds = time.perf_counter() - started  # (both searches)
        return report

    def _run_once(self) -> tuple[Report, FloatArray, list[FloatArray]]:
        """The loop once: the report, its final model's held-out error and parameters."""
        started = time.perf_counter()
        problem = self.problem
        report = Report(problem.nominal, problem.split, notes=list(hook(problem, "notes")))
        effects: list[Any] = []
        params: list[FloatArray] = []
        held_err = problem.error(effects, params, True)
        report.heldout_rmse_nominal = rmse(held_err)
        remaining = [c for c in problem.candidates() if not getattr(c, "declared", False)]
        floor = problem.noise_floor()
        # effects whose size the recording declares (no parameter fitted) come first, each
        # named where it improves the held-out fit: known physics is in the model before
        # anything is searched for (a fitted constant torque would take the declared weight).
        # One that does not improve it yet is tried again after each effect found (a large
        # missing effect may hide it)
        effects, params, held_err = self._declared(report, effects, params, held_err, floor)
        remaining = not_named(remaining, effects)
        effects, params, held_err, remaining, closest = self._search(
            report, effects, params, held_err, remaining
        )
        searched = effects
        effects, params = rivals_again(self, report, effects, params, floor)
        effects, params = still_needed(self, report, effects, params, floor)
        effects, params = variants_again(self, report, effects, params, floor)
        effects, params = friction_given_away(self, report, effects, params, floor)
        if effects is not searched:  # (each returns the model it was given where it keeps it)
            held_err = problem.error(effects, params, True)
        effects, params, held_err = self._checked_last(
            report, effects, params, held_err, remaining=remaining, floor=floor
        )
        effects, params, held_err = self._on_load_cell(report, effects, params, held_err)
        effects, params, held_err = told_from_nothing(self, report, effects, params, held_err)
        report.notes += [
            f"not named: {c.describe()}; {self._unnamed(c)}"
            for c in self._pending_declared(effects)
            if getattr(c, "shown", False) and hasattr(c, "unnamed") and id(c) in self._refused
        ]
        report.fitted = list(zip(effects, params, strict=True))
        widen(report, hook(problem, "model_error_share"))
        report.final_heldout_rmse = rmse(held_err)
        report.unexplained = leftover(
            problem,
            held_err,
            effects,
            params,
            None if closest is None else ([c.name for c in closest.added], closest.gain),
        )
        report.seconds = time.perf_counter() - started
        return report, held_err, params

    def _search(
        self,
        report: Report,
        effects: list[Any],
        params: list[FloatArray],
        held_err: FloatArray,
        remaining: list[Any],
    ) -> tuple[list[Any], list[FloatArray], FloatArray, list[Any], Step | None]:
        """Rounds of the search from the model (effects, parameters, held-out error) until no
        structure is left or nothing names: (effects, parameters, held-out error, the
        candidates not named, the closest refused step)."""
        problem = self.problem
        floor = problem.noise_floor()
        declared = hook(problem, "declared_stage")
        closest: Step | None = None
        left = hook(problem, "structure_left")
        pairs = hook(problem, "pairs")
        while remaining and left(held_err):
            base = Base(
                held_err, rmse(held_err), aic(held_err, total(params)), floor, effects, params
            )
            singles = [self._single(effects, params, cand, base) for cand in remaining]
            step = self._choose([s for s in singles if self._names(s, base)])
            if step is None and declared:
                # a declared effect a large missing one hid: the two together
                step = self._choose(
                    [
                        s
                        for s in with_declared(self, effects, singles, base, remaining)
                        if self._names(s, base)
                    ]
                )
            beyond = beyond_range(self, singles, base) if step is None else []
            if step is None and pairs and unexplained_phases(problem, held_err):
                # a phase unexplained (3x the floor; not below: a pair fitted to nearly noise
                # explains noise) that no single effect explains: two missing effects may each
                # explain too little alone (zoo_12167: 2.8x the floor in all, 7x at impact)
                self.progress("no single effect explains it: trying pairs")
                step = self._choose(
                    [
                        s
                        for s in fitted_pairs(self, effects, params, singles, base, beyond=beyond)
                        if self._names(s, base)
                    ]
                )
            if step is None:
                # (a candidate refused as not meaningful, e.g. pinned at a bound, is no answer)
                if beyond:  # (the pairs kept to it, or were not tried: said why)
                    report.notes.append(out_of_range(beyond))
                closest = max(
                    (s for s in singles if s.meaningful), key=lambda s: s.gain, default=None
                )
                break
            if step.behind is not None and other_way(self, step.behind):
                step = taken(step, step.behind)
            first_rmse = base.rmse
            for k, cand in enumerate(step.added):
                # a pair: the first is reported with what it removes alone
                after = step.rmse if k == len(step.added) - 1 else step.alone_rmse[k]
                report.findings.append(self._finding(cand, step, base, first_rmse, after))
                first_rmse = after
                self.progress(f"found {cand.name}: {report.findings[-1].evidence}")
            effects = [*effects, *step.added]
            if len(step.added) == 1 and not step.shown:
                self._searched.add(id(step.added[0]))
            params, held_err = step.params, step.err
            if step.joint:  # every parameter refitted: the findings' values and intervals
                intervals = interval(step.result, step.result.x)
                update_findings(report, effects, params, intervals)
            if declared:
                effects, params, held_err = self._declared(report, effects, params, held_err, floor)
            remaining = not_named(remaining, effects)
        return effects, params, held_err, remaining, closest

    def _on_load_cell(
        self,
        report: Report,
        effects: list[Any],
        params: list[FloatArray],
        held_err: FloatArray,
    ) -> tuple[list[Any], list[FloatArray], FloatArray]:
        """The candidates not named, searched once more on a second channel of the recording
        (``force_view`` of the problem: a drop test's load cell while the shuttle rides the
        arm, drop_force), the effects found held: a torque of a few hundredths of a newton
        metre the encoder shows within a count the load cell shows at tens of its noise."""
        view = hook(self.problem, "force_view")()
        remaining = [
            c
            for c in not_named(list(self.problem.candidates()), effects)
            # (what acts on the encoder's readings alone the load cell does not see)
            if not getattr(c, "declared", False) and getattr(c, "sensor", None) is None
        ]
        if view is None or not remaining:
            return effects, params, held_err
        view.start(effects, params)
        if not view.usable():  # (too little of the ride left where the shuttle settled)
            return effects, params, held_err
        self.progress("searching the load cell")
        # (the loop's own class: a subclass that logs its steps, benchmarks/share_calibration)
        stage = type(self)(view, min_improvement=self.min_improvement, progress=self.progress)
        found = len(effects)
        effects, params, *_ = stage._search(
            report, effects, params, view.error(effects, params, True), remaining
        )
        if len(effects) == found:
            return effects, params, held_err
        return effects, params, self.problem.error(effects, params, True)

    def _declared(
        self,
        report: Report,
        effects: list[Any],
        params: list[FloatArray],
        held_err: FloatArray,
        floor: float,
    ) -> tuple[list[Any], list[FloatArray], FloatArray]:
        """Each declared effect not yet in the model, added where it improves the held-out
        fit (lower RMSE, information criterion better by 10) or where the recording shows it
        acting (``shown``: a drive's recorded torque held at its limit, a shuttle striking the
        arm again), or where a second channel shows it (``shows_elsewhere`` of the problem: a
        drop test's load cell reads the shuttle's weight while it rides the arm, which a
        missing sensor delay may hide from the encoder), or where an effect named before it
        had taken its place (``stood_in``: an offset fitted at the weight). What is fitted of
        it must be told from nothing (its 95 % interval without its null value): a load cell
        showed a shuttle chatter on a rig whose contact is nearly inelastic, and the rebound
        fitted there was 0.007 (-0.09 to 0.10). A shown effect is meaningful only at a size it shows
        (a rebound: a coefficient that is more than the chatter of a stiff contact)."""
        return self._each_added(
            report,
            (effects, params, held_err),
            self._pending_declared(effects),
            floor,
            self._takes_declared,
        )

    def _takes_declared(self, step: Step, base: Base) -> bool:
        """Whether a declared effect is named (_declared)."""
        return (
            step.meaningful
            and not null_inside(step)
            and (
                step.shown
                or all(getattr(a, "shown", False) for a in step.added)
                or (step.rmse < base.rmse and step.aic < base.aic - CRITERION)
                or hook(self.problem, "shows_elsewhere")(step, base)
                or stood_in(step, base)
            )
        )

    def _checked_last(
        self,
        report: Report,
        effects: list[Any],
        params: list[FloatArray],
        held_err: FloatArray,
        *,
        remaining: list[Any],
        floor: float,
    ) -> tuple[list[Any], list[FloatArray], FloatArray]:
        """Properties of the readings (``checked_last`` of a candidate: the encoder's lattice)
        not named in the search, tried once more by the same rule (_names) whatever is left.
        The search stops at the noise floor, and the floor counts the lattice's own error (a
        count / sqrt 12): a model finer than a coarse encoder's counts stopped it there, with
        the lattice unnamed (6 of 17 coarse encoders on the zoo's fresh seeds 9300-9399). Here
        it is judged against the floor without its own error (``sensor_scope`` after the
        search); in the search, against the whole floor, as before."""
        return self._each_added(
            report,
            (effects, params, held_err),
            [c for c in remaining if getattr(c, "checked_last", False)],
            floor,
            self._names,
            after_search=True,
        )

    def _each_added(
        self,
        report: Report,
        model: tuple[list[Any], list[FloatArray], FloatArray],
        candidates: list[Any],
        floor: float,
        accept: Callable[[Step, Base], bool],
        *,
        after_search: bool = False,
    ) -> tuple[list[Any], list[FloatArray], FloatArray]:
        """Each of ``candidates`` in turn added to the model (effects, parameters, held-out
        error) where ``accept`` takes it, and reported. A shown effect with a ``rival`` (an
        effect that makes the same sign in the recording: a ring of a compliant arm throws
        the shuttle off as a rebound does) gives way to it where the shown effect's
        ``yields`` says the rival explains the recordings as well: the rival stands for what
        the recording shows, and the shown effect is tried again on top of it (named where
        its interval excludes its null). Each effect added sends those refused before it back
        to be tried again (a large missing effect may hide a declared one)."""
        effects, params, held_err = model
        queue, waiting = list(candidates), []
        while queue:
            cand = queue.pop(0)
            base = Base(
                held_err, rmse(held_err), aic(held_err, total(params)), floor, effects, params
            )
            step = self._single(effects, params, cand, base, after_search=after_search)
            rival = self._rival_instead(effects, params, cand, step, base)
            if rival is not None and accept(rival, base) and not other_way(self, step):
                queue.insert(0, cand)  # tried again on top of its rival
                step, cand = rival, rival.added[0]
            elif not accept(step, base):
                waiting.append(cand)
                if getattr(cand, "shown", False):
                    self._refused[id(cand)] = step
                continue
            # those refused so far are tried again with it (it may have hidden them)
            queue, waiting = [*waiting, *queue], []
            report.findings.append(self._finding(cand, step, base, base.rmse, step.rmse))
            self.progress(f"found {cand.name}: {report.findings[-1].evidence}")
            effects, params, held_err = [*effects, cand], step.params, step.err
            if step.joint:  # every parameter refitted with it: the findings' values and intervals
                update_findings(report, effects, params, interval(step.result, step.result.x))
        return effects, params, held_err

    def _unnamed(self, cand: Any) -> str:
        """Why shown ``cand`` was not named: its last refused fit, and whether that fit's
        interval held its null (worked out here, once, for the effects left unnamed)."""
        step = self._refused[id(cand)]
        return str(cand.unnamed(step.new()[-1][1], null_inside(step)))

    def _rival_instead(
        self, effects: list[Any], params: list[FloatArray], cand: Any, step: Step, base: Base
    ) -> Step | None:
        """The step of ``cand``'s ``rival`` where ``cand`` yields to it (``yields``: its own
        rule, from both fits), marked as standing for what the recording shows; None where
        it has no rival, the rival is in the model already, or it does not yield."""
        rival = getattr(cand, "rival", None)
        if rival is None or any(same(rival, e) for e in effects):
            return None
        other = self._single(effects, params, rival, base)
        own, its = step.new()[0][1], other.new()[0][1]
        if not (other.meaningful and cand.yields(own, its, other.rmse / step.rmse)):
            return None
        other.shown = True
        other.alternatives = [cand.alike(own, step.rmse / other.rmse)]
        other.alike = [step]  # (its fitted values in the finding: findings.alike_fits)
        return other

    def _finding(self, cand: Any, step: Step, base: Base, before: float, after: float) -> Any:
        return finding(self.problem, cand, step, base, before=before, after=after)

    def _pending_declared(self, effects: list[Any]) -> list[Any]:
        """The declared effects (``declared`` of a candidate) not yet in the model."""
        return [
            c
            for c in self.problem.candidates()
            if getattr(c, "declared", False) and all(c is not e for e in effects)
        ]

    def _single(
        self,
        effects: list[Any],
        params: list[FloatArray],
        cand: Any,
        base: Base,
        *,
        after_search: bool = False,
        start: FloatArray | None = None,
    ) -> Step:
        """``cand`` added to the effects found so far: its own parameters fitted (from
        ``start``, None: its own), then all of them together (an effect found earlier may have
        stood in for part of this one). A drift ``reduced`` to the terms that drifted is taken
        where it explains the held-out recordings alike (both fits meaningful)."""
        self.progress(f"trying {cand.name}")
        x, result = fit_candidate(self.problem, effects, params, cand, start)
        joint, together = (
            refit(self.problem, [*effects, cand], [*params, x])
            if hook(self.problem, "joint_refit")
            else ([*params, x], None)
        )
        if together is None:
            step = self._step(
                effects, [*params, x], [cand], result, base, after_search=after_search
            )
        else:
            step = self._step(effects, joint, [cand], together, base, after_search=after_search)
            step.joint = True
        smaller = getattr(cand, "reduced", lambda _p: None)(step.params[-1])
        if smaller is not None and step.meaningful:
            held = self._single(
                effects, params, smaller[0], base, after_search=after_search, start=smaller[1]
            )
            if held.rmse <= ALIKE * step.rmse and held.meaningful:
                return held
        return step

    def _step(
        self,
        effects: list[Any],
        params: list[FloatArray],
        added: list[Any],
        result: Any,
        base: Base,
        *,
        after_search: bool = False,
    ) -> Step:
        err = self.problem.error([*effects, *added], params, True)
        err_rmse = rmse(err)
        size = total(params[: len(effects)]) + sum(
            parameter_count(a, p) for a, p in zip(added, params[len(effects) :], strict=True)
        )
        judged = self._judged(added, base, err, after_search)
        return Step(
            added=added,
            params=params,
            err=err,
            rmse=err_rmse,
            aic=aic(err, size),
            gain=share_removed(*judged),  # (of one sensor's error: _judged)
            judged=judged,
            scanned=scan_facts(self.problem, effects, added, params),
            result=result,
            # (and, where the problem says which, not at the cost of what it does not judge:
            # a load-cell fit that worsens the kinematics, drop_force)
            meaningful=all(
                a.meaningful(p) for a, p in zip(added, params[len(effects) :], strict=True)
            )
            and not driven_to_bound(effects, params, base)
            and self.accepts([*effects, *added], params),
        )

    def accepts(self, effects: Sequence[Any], params: Sequence[FloatArray]) -> bool:
        """Whether the problem allows this model whatever it explains (its optional
        ``accepts``: a drop test's rail friction the falls contradict); True without one."""
        return bool(hook(self.problem, "accepts")(effects, params))

    def _judged(
        self, added: list[Any], base: Base, err: FloatArray, after_search: bool = False
    ) -> tuple[float, float, float]:
        """(RMSE before, after, floor) of the held-out error ``added`` is judged on: all of
        it; for effects of one sensor's readings (``sensor_scope`` of the problem, which knows
        the effects found), or where only one sensor's error is left above its floor
        (``leftover_scope``), that sensor's error and its own floor."""
        scoped = hook(self.problem, "sensor_scope")
        scope = scoped(added, after_search, base.effects)
        if scope is None and base.rmse <= SIGNIFICANT * base.floor:
            # the pooled error is near its floor: what is left is one sensor's, judged there
            scope = hook(self.problem, "leftover_scope")(base.err)
        if scope is None:
            return base.rmse, rmse(err), base.floor
        mask, floor = scope
        return rmse(base.err[mask]), rmse(err[mask]), floor

    def _names(self, step: Step, base: Base, share: float | None = None) -> bool:
        """Whether ``step`` names its effects: it removes at least ``share`` (None:
        ``min_improvement``) of the
        held-out error above the noise floor, a tenth of the floor at least (both on the error
        it is judged on, see _judged), improves the information criterion by 10, every effect
        in it is meaningful (no drift scales near 1, no fit against a bound, no rebound below
        what it shows) and its interval excludes its null value; a pair also beats each of
        its members alone by 10; where the problem searches below SIGNIFICANT times the floor
        (``to_the_floor``), a step judged there takes it down to the floor
        (``short_of_floor``). A missing effect that is really there explains most of what
        is left; one that stands in for something else explains part of it."""
        return (
            step.meaningful
            and not null_inside(step)
            and step.judged[0] - step.judged[1] >= 0.1 * step.judged[2]
            and step.gain >= self._share(step, share)
            and step.aic < base.aic - CRITERION
            and all(step.aic < a - CRITERION for a in step.alone_aic)
            and not (hook(self.problem, "to_the_floor") and short_of_floor(step))
        )

    def _share(self, step: Step, share: float | None = None) -> float:
        return share_needed(step, self.min_improvement if share is None else share)

    def _choose(self, steps: list[Step]) -> Step | None:
        return choose(steps, hook(self.problem, "expected"))


def discover(
    model: NominalModel,
    trials: Sequence[Trial],
    *,
    window_s: float = 0.1,
    candidates: Sequence[Effect] | None = None,
    **kwargs: Any,
) -> Report:
    """The loop on 1-DoF torque-driven trials."""
    if len(trials) < 1:
        raise ModelError("no trials to analyse")
    problem = TorqueDrivenProblem(model, trials, window_s=window_s, candidates=candidates)
    return Discoverer(problem, **kwargs).run()
