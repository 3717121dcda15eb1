"""Proprioceptive torque estimation and contact detection (eq. 1), ROS-free.

Estimate. tau_hat = k_s (theta_d - theta_a) [+ k_d (theta_d' - theta_a')] [- beta theta_a']:
the virtual series-elastic spring of the impedance controller (eq. 1), with the damping and
back-EMF terms of the full estimate available by configuration.

Detection acts on the position error, as in the paper (0.1 rad for drop tests; e_s + epsilon
with k_s epsilon = 0.02 N m for the feel-cage task), through a Schmitt trigger per joint:
* signal = |theta_d - theta_a - bias| (bias: a known steady error to subtract; default 0);
* two levels, *contact* and *collision*, each with an onset and a lower release level;
* onset and release dwell times: the signal must stay beyond a level that long;
* an onset event carries the stamp of the sample that first crossed the level (the paper's t_e),
  even when the dwell time confirms it later;
* settings per joint, changeable at runtime, and a reset.

Time is passed in as the samples' stamps, integer nanoseconds (a header stamp's sec * 1e9 +
nanosec): an event carries the very stamp of its sample, never a float rounded back. Nothing
here reads a clock.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from enum import Enum
from functools import cached_property

import numpy as np
import numpy.typing as npt

from transparency_ros.core import stamps
from transparency_ros.core.errors import TransparencyError
from transparency_ros.core.setpoint_join import Setpoints


class EstimatorError(TransparencyError, ValueError):
    """Estimator or detector settings out of range or inconsistent."""


@dataclass(frozen=True)
class EstimatorGains:
    k_s_nm_per_rad: float = 2.0
    k_d_nms_per_rad: float = 0.0
    beta_nms_per_rad: float = 0.0  # back-EMF term of the full estimate

    def validated(self) -> EstimatorGains:
        for name in ("k_s_nm_per_rad", "k_d_nms_per_rad", "beta_nms_per_rad"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise EstimatorError(f"{name} must be finite and >= 0, got {value}")
        if self.k_s_nm_per_rad == 0:
            raise EstimatorError("k_s_nm_per_rad must be > 0")
        return self

    def torque(
        self,
        theta_d: float,
        theta_a: float,
        theta_d_dot: float = 0.0,
        theta_a_dot: float = 0.0,
    ) -> float:
        """Eq. (1), optionally with the damping and back-EMF terms."""
        return (
            self.k_s_nm_per_rad * (theta_d - theta_a)
            + self.k_d_nms_per_rad * (theta_d_dot - theta_a_dot)
            - self.beta_nms_per_rad * theta_a_dot
        )


def estimate_torque(
    gains: EstimatorGains,
    theta_d: npt.ArrayLike,
    theta_a: npt.ArrayLike,
    theta_d_dot: npt.ArrayLike = 0.0,
    theta_a_dot: npt.ArrayLike = 0.0,
) -> npt.NDArray[np.float64]:
    """Eq. (1) over arrays (bag evaluation, comparisons)."""
    d, a = np.asarray(theta_d, dtype=float), np.asarray(theta_a, dtype=float)
    dd, ad = np.asarray(theta_d_dot, dtype=float), np.asarray(theta_a_dot, dtype=float)
    return np.asarray(
        gains.k_s_nm_per_rad * (d - a)
        + gains.k_d_nms_per_rad * (dd - ad)
        - gains.beta_nms_per_rad * ad,
        dtype=np.float64,
    )


class ContactLevel(int, Enum):
    NONE = 0
    CONTACT = 1
    COLLISION = 2


@dataclass(frozen=True)
class DetectorSettings:
    """Schmitt-trigger levels on the detection signal (rad for the position error, or N m
    when used on a torque residual), and dwell times."""

    contact_onset: float = 0.1
    contact_release: float = 0.05
    collision_onset: float = math.inf  # off unless configured
    collision_release: float = math.inf
    onset_dwell_s: float = 0.0
    release_dwell_s: float = 0.0
    bias: float = 0.0

    def validated(self) -> DetectorSettings:
        problems = []
        if not (self.contact_onset > 0 and math.isfinite(self.contact_onset)):
            problems.append(f"contact_onset must be > 0, got {self.contact_onset}")
        if not 0 <= self.contact_release < self.contact_onset:
            problems.append(
                f"contact_release must satisfy 0 <= release < onset "
                f"({self.contact_release} vs {self.contact_onset})"
            )
        if not self.collision_onset > self.contact_onset:
            problems.append(
                f"collision_onset ({self.collision_onset}) must be above contact_onset "
                f"({self.contact_onset})"
            )
        if math.isinf(self.collision_onset):
            if not math.isinf(self.collision_release):
                problems.append("collision_release is set but collision_onset is not")
        elif not self.contact_release <= self.collision_release < self.collision_onset:
            problems.append(
                f"collision_release must satisfy contact_release <= release < collision_onset "
                f"({self.collision_release})"
            )
        for name in ("onset_dwell_s", "release_dwell_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                problems.append(f"{name} must be finite and >= 0, got {value}")
        if not math.isfinite(self.bias):
            problems.append("bias must be finite")
        if problems:
            raise EstimatorError("; ".join(problems))
        return self

    @property
    def onset_dwell_ns(self) -> int:
        """The onset dwell in integer nanoseconds, to compare with stamp differences (computed
        once per settings, not per sample)."""
        return self._dwell_ns[0]

    @property
    def release_dwell_ns(self) -> int:
        return self._dwell_ns[1]

    @cached_property
    def _dwell_ns(self) -> tuple[int, int]:
        return round(self.onset_dwell_s * 1e9), round(self.release_dwell_s * 1e9)

    def onset_level(self, level: ContactLevel) -> float:
        return self.collision_onset if level is ContactLevel.COLLISION else self.contact_onset

    def release_level(self, level: ContactLevel) -> float:
        return self.collision_release if level is ContactLevel.COLLISION else self.contact_release


class EventKind(str, Enum):
    CONTACT_ONSET = "contact_onset"
    COLLISION_ONSET = "collision_onset"
    COLLISION_RELEASE = "collision_release"  # back to contact
    RELEASE = "release"  # back to no contact


@dataclass(frozen=True)
class ContactEvent:
    kind: EventKind
    joint: str
    stamp_ns: int  # stamp of the sample that crossed the level
    confirmed_ns: int  # stamp of the sample that confirmed it (after the dwell time)
    signal: float
    torque_nm: float
    level: ContactLevel  # state after the event


@dataclass
class _JointState:
    level: ContactLevel = ContactLevel.NONE
    pending_up: tuple[ContactLevel, int] | None = None  # (target level, first crossing stamp)
    pending_down_since: int | None = None


@dataclass
class SchmittDetector:
    """Per-joint two-level Schmitt trigger with dwell times."""

    default: DetectorSettings = field(default_factory=DetectorSettings)
    per_joint: dict[str, DetectorSettings] = field(default_factory=dict)
    _joints: dict[str, _JointState] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.default = self.default.validated()
        for joint, settings in self.per_joint.items():
            self.per_joint[joint] = settings.validated()

    def settings_for(self, joint: str) -> DetectorSettings:
        return self.per_joint.get(joint, self.default)

    def configure(self, joint: str | None = None, **changes: float) -> DetectorSettings:
        """Change settings at runtime (all joints' default when ``joint`` is None); atomic."""
        base = self.default if joint is None else self.settings_for(joint)
        new = replace(base, **changes).validated()
        if joint is None:
            self.default = new
        else:
            self.per_joint[joint] = new
        return new

    def reset(self, joint: str | None = None) -> None:
        if joint is None:
            self._joints.clear()
        else:
            self._joints.pop(joint, None)

    def level(self, joint: str) -> ContactLevel:
        return self._joints.get(joint, _JointState()).level

    def update(self, joint: str, stamp_ns: int, signal: float, torque_nm: float
               ) -> list[ContactEvent]:  # fmt: skip
        """Feed one sample stamped ``stamp_ns`` [ns]; return the events it completes (usually
        none)."""
        s = self.settings_for(joint)
        st = self._joints.setdefault(joint, _JointState())
        value = abs(signal - s.bias)
        events: list[ContactEvent] = []
        # rising: the highest level whose onset the signal exceeds, above the current one
        target = ContactLevel.NONE
        if value >= s.collision_onset:
            target = ContactLevel.COLLISION
        elif value >= s.contact_onset:
            target = ContactLevel.CONTACT
        if target > st.level:
            if st.pending_up is None or st.pending_up[0] < target:
                first = st.pending_up[1] if st.pending_up is not None else stamp_ns
                st.pending_up = (target, first)
            up_target, first = st.pending_up
            if stamp_ns - first >= s.onset_dwell_ns:
                for lvl in range(st.level + 1, up_target + 1):
                    new = ContactLevel(lvl)
                    kind = (
                        EventKind.COLLISION_ONSET
                        if new is ContactLevel.COLLISION
                        else EventKind.CONTACT_ONSET
                    )
                    events.append(ContactEvent(kind, joint, first, stamp_ns, value, torque_nm, new))
                st.level = up_target
                st.pending_up = None
            st.pending_down_since = None
            return events
        st.pending_up = None
        # falling: below the release level of the current state
        if st.level is not ContactLevel.NONE and value <= s.release_level(st.level):
            if st.pending_down_since is None:
                st.pending_down_since = stamp_ns
            if stamp_ns - st.pending_down_since >= s.release_dwell_ns:
                below = ContactLevel(st.level - 1)
                # drop straight to NONE when also below the contact release level
                if below is ContactLevel.CONTACT and value <= s.contact_release:
                    below = ContactLevel.NONE
                kind = (
                    EventKind.COLLISION_RELEASE
                    if below is ContactLevel.CONTACT
                    else EventKind.RELEASE
                )
                events.append(
                    ContactEvent(
                        kind, joint, st.pending_down_since, stamp_ns, value, torque_nm, below
                    )
                )
                st.level = below
                st.pending_down_since = None
        else:
            st.pending_down_since = None
        return events


@dataclass(frozen=True)
class ThresholdProposal:
    steady_error_rad: float  # e_s: largest |error| in the quiet recording
    noise_std_rad: float
    epsilon_rad: float
    contact_onset_rad: float
    contact_release_rad: float
    collision_onset_rad: float
    collision_release_rad: float


def propose_thresholds(
    errors_rad: npt.ArrayLike,
    k_s_nm_per_rad: float,
    *,
    epsilon_nm: float = 0.02,
    noise_sigmas: float = 5.0,
    collision_factor: float = 5.0,
) -> ThresholdProposal:
    """Thresholds from a quiet recording (no contact): the paper's e_s + epsilon, k_s eps = 0.02.

    epsilon is raised to ``noise_sigmas`` standard deviations of the sample noise (estimated
    from first differences, so slow ripple counts towards e_s, not noise) when that is larger.
    Release levels sit halfway between e_s and the onset; the collision level is
    ``collision_factor`` epsilons above e_s.
    """
    e = np.asarray(errors_rad, dtype=float)
    if e.size < 10 or not np.all(np.isfinite(e)):
        raise EstimatorError("a quiet recording needs >= 10 finite error samples")
    if not k_s_nm_per_rad > 0:
        raise EstimatorError("k_s must be > 0")
    e_s = float(np.max(np.abs(e)))
    # sample-to-sample noise; slow ripple belongs to e_s, not to the noise
    noise = float(np.std(np.diff(e)) / math.sqrt(2.0))
    eps = max(epsilon_nm / k_s_nm_per_rad, noise_sigmas * noise)
    return ThresholdProposal(
        steady_error_rad=e_s,
        noise_std_rad=noise,
        epsilon_rad=eps,
        contact_onset_rad=e_s + eps,
        contact_release_rad=e_s + eps / 2,
        collision_onset_rad=e_s + collision_factor * eps,
        collision_release_rad=e_s + collision_factor * eps / 2,
    )


class SampleRejectedError(EstimatorError):
    """A joint sample or command the estimator will not use; ``reason`` is a short key."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


@dataclass(frozen=True)
class JointEstimate:
    joint: str
    stamp_ns: int
    error_rad: float  # theta_d - theta_a
    torque_nm: float  # tau_hat


@dataclass
class EstimatorPipeline:
    """Samples in, estimates and contact events out; counts what it rejects, never raises on data.

    theta_d comes from the driver's setpoint for the sample when given (``core.setpoint_join``;
    a NaN theta_d there: the motor was not held, the joint gets no estimate), else from the
    latest command for the joint, else ``default_theta_d_rad``. A stamped command with a velocity
    is a streamed trajectory: theta_d at a sample's stamp is theta_d + theta_d' (stamp - command
    stamp), as the driver applies it between updates. Where both a setpoint and a command are
    known, their difference at the latest sample is kept per joint (``theta_d_gap``): a command
    the driver clamped, stopped following after its timeout, or one of the two missed.
    """

    gains: EstimatorGains = field(default_factory=EstimatorGains)
    detector: SchmittDetector = field(default_factory=SchmittDetector)
    joints: frozenset[str] = frozenset()  # empty: accept any joint name
    default_theta_d_rad: float = 0.0
    rejected: dict[str, int] = field(default_factory=dict)
    samples: int = 0
    not_driven: int = 0  # joint samples without an estimate: the driver did not hold them
    # joint -> |theta_d of its latest command - the driver's setpoint| at its latest sample [rad]
    theta_d_gap: dict[str, float] = field(default_factory=dict)
    _commands: dict[str, tuple[float, float, int | None]] = field(default_factory=dict)
    _last_stamp: dict[str, int] = field(default_factory=dict)

    def reject(self, reason: str, detail: str) -> SampleRejectedError:
        """Count a rejection under ``reason``; the error to raise (or drop) with ``detail``."""
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        return SampleRejectedError(reason, detail)

    def _check_arrays(self, names: list[str], arrays: dict[str, list[float]]) -> None:
        if not names:
            raise self.reject("no_names", "a sample must name its joints")
        if len(set(names)) != len(names):  # found by hypothesis: one joint updated twice
            raise self.reject("duplicate_joint", f"a joint named twice in {names}")
        for label, values in arrays.items():
            if values and len(values) != len(names):
                raise self.reject(
                    "length_mismatch", f"{len(values)} {label} for {len(names)} names"
                )
        unknown = [n for n in names if self.joints and n not in self.joints]
        if unknown:
            raise self.reject("unknown_joint", f"{unknown} not in {sorted(self.joints)}")

    def command(self, names: list[str], positions: list[float], velocities: list[float],
                stamp_ns: int | None = None, efforts: Sequence[float] = ()) -> None:  # fmt: skip
        """A /joint_commands message: theta_d (and theta_d') per joint, stamped [ns] or not.
        Without positions but with ``efforts`` it is a pure torque command (the driver drives
        the joint by torque alone, as the feel-cage's act phase does): the joints are then not
        held at a position and get no estimate, as a NaN setpoint says, until a position
        command."""
        if stamp_ns is not None:
            stamp_ns = operator.index(stamp_ns)  # an int: a float stamp is a caller's bug
        arrays = {"positions": positions, "velocities": velocities, "efforts": list(efforts)}
        self._check_arrays(names, arrays)
        if not positions and not efforts:
            raise self.reject("no_position", "a command needs positions (or efforts: torque)")
        values = list(positions) + list(velocities) + list(efforts)
        if not all(math.isfinite(v) for v in values):
            raise self.reject("not_finite", "NaN or inf in a command")
        for i, name in enumerate(names):
            if not positions:  # pure torque: not held
                self._commands[name] = (math.nan, 0.0, stamp_ns)
                continue
            self._commands[name] = (positions[i], velocities[i] if velocities else 0.0, stamp_ns)

    def _commanded(self, name: str, stamp_ns: int) -> tuple[float, float] | None:
        """theta_d, theta_d' of the latest command for ``name`` at ``stamp_ns`` (None: none)."""
        if name not in self._commands:
            return None
        theta_d, theta_d_dot, command_stamp = self._commands[name]
        if command_stamp is not None and theta_d_dot != 0.0:
            theta_d += theta_d_dot * (stamp_ns - command_stamp) * 1e-9
        return theta_d, theta_d_dot

    def _theta_d(self, name: str, stamp_ns: int, setpoints: Setpoints | None
                 ) -> tuple[float, float]:  # fmt: skip
        commanded = self._commanded(name, stamp_ns)
        if setpoints is None or name not in setpoints:
            return commanded or (self.default_theta_d_rad, 0.0)
        theta_d, theta_d_dot = setpoints[name]
        if commanded is not None and not (math.isnan(theta_d) or math.isnan(commanded[0])):
            self.theta_d_gap[name] = abs(commanded[0] - theta_d)
        return theta_d, theta_d_dot

    def sample(
        self, stamp_ns: int, names: list[str], positions: list[float], velocities: list[float],
        setpoints: Setpoints | None = None,
    ) -> tuple[list[JointEstimate], list[ContactEvent]]:  # fmt: skip
        """A /joint_states message stamped ``stamp_ns`` [ns], with the driver's ``setpoints``
        for it if known. Raises SampleRejectedError (counted) for a bad sample."""
        stamp_ns = operator.index(stamp_ns)  # an int: a float stamp is a caller's bug
        self._check_arrays(names, {"positions": positions, "velocities": velocities})
        if not positions:
            raise self.reject("no_position", "a joint state needs positions")
        values = list(positions) + list(velocities)
        if not all(math.isfinite(v) for v in values):
            raise self.reject("not_finite", "NaN or inf in a joint state")
        for name in names:
            last = self._last_stamp.get(name)
            if last is not None and stamp_ns <= last:
                raise self.reject(
                    "stamp_not_increasing",
                    f"{name}: {stamps.text(stamp_ns)} after {stamps.text(last)}",
                )
        estimates: list[JointEstimate] = []
        skipped = 0
        for i, name in enumerate(names):
            theta_d, theta_d_dot = self._theta_d(name, stamp_ns, setpoints)
            if math.isnan(theta_d):  # the driver did not hold it: no position error to read
                skipped += 1
                continue
            velocity = velocities[i] if velocities else 0.0
            error = theta_d - positions[i]
            torque = self.gains.torque(theta_d, positions[i], theta_d_dot, velocity)
            if not (math.isfinite(error) and math.isfinite(torque)):  # finite, but too large
                raise self.reject("out_of_range", f"{name}: the estimate overflows ({torque})")
            estimates.append(JointEstimate(name, stamp_ns, error, torque))
        # only a sample accepted whole changes the state
        self.samples += 1
        self.not_driven += skipped
        for name in names:
            self._last_stamp[name] = stamp_ns
        events: list[ContactEvent] = []
        for estimate in estimates:
            events += self.detector.update(
                estimate.joint, stamp_ns, estimate.error_rad, estimate.torque_nm
            )
        return estimates, events

    def reset(self) -> None:
        self.detector.reset()
        self._last_stamp.clear()
        self.not_driven = 0
        self.theta_d_gap.clear()
