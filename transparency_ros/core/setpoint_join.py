"""Pair each /joint_states sample with the setpoint the driver applied to it, ROS-free.

The driver publishes, for every sample, a /joint_setpoints message with the same stamp and the
same joint names (``ros.actuator_driver.messages``): theta_d and theta_d' per joint, NaN where
the motor was not held at a position. An estimator that took theta_d from /joint_commands on its
own could disagree with the driver: a command one of them missed (a publisher that exits right
after sending, an estimator started later), a target the driver clamped or stopped following
after its command timeout. Pairing by stamp removes the guess.

The two topics arrive separately, in either order. :class:`SetpointJoin` keeps the setpoints
of recent stamps and holds back a sample whose setpoint has not come yet, releasing samples
first in, first out:

* **matched**: the setpoint of the sample's stamp is there (before or after the sample);
* **missing**: a joint that gets setpoints, but the sample's never came: a later setpoint of its
  joints arrived, or the sample waited ``max_wait_s``. The setpoint of the nearest stamp stands
  in (the driver holds its setpoint between commands), and the estimator reports the loss;
* **before the first**: samples sent before this node heard the setpoint stream (it is matched
  after the state stream at start-up): the first setpoint heard stands in;
* **unpaired**: joints whose source publishes no setpoints (another driver, a bag without them,
  a driver with ``publish_setpoints:=false``). Found out once: the first samples of a joint never
  seen with a setpoint wait ``first_wait_s`` (the setpoint publisher may be matched after the
  state publisher; ``expected_wait_s`` while the caller sees one that has not been heard yet),
  then its samples pass straight on, until a setpoint names it.

Waits are measured on the caller's clock (``now_s``: when a message arrived, and
:meth:`SetpointJoin.expire` for samples that wait while nothing arrives); pairing is by the
stamps [ns] alone.
"""

from __future__ import annotations

import math
from collections import OrderedDict, deque
from dataclasses import dataclass, field

# joint -> (theta_d [rad], theta_d' [rad/s]); theta_d NaN: the motor was not held at a position
Setpoints = dict[str, tuple[float, float]]


@dataclass(frozen=True)
class StateSample:
    stamp_ns: int
    names: list[str]
    positions: list[float]
    velocities: list[float]


@dataclass(frozen=True)
class Paired:
    """A sample and the driver's setpoints for it (None: none; theta_d from the commands)."""

    sample: StateSample
    setpoints: Setpoints | None
    missing: bool = False  # its joints get setpoints, but this sample's was lost


@dataclass
class SetpointJoin:
    max_wait_s: float = 0.02
    first_wait_s: float = 1.0
    # while the caller knows of a setpoint publisher not heard yet (discovery under way), the
    # first samples of a joint wait up to this long
    expected_wait_s: float = 5.0
    expected: bool = False
    max_kept: int = 10_000  # setpoints kept waiting for their sample
    max_pending: int = 20_000  # samples held back (then released without setpoints)
    matched: int = 0
    missing: int = 0
    unpaired_samples: int = 0
    before_first: int = 0  # samples older than the first setpoint heard (the first one's used)
    unpaired: set[str] = field(default_factory=set)  # joints whose source sends no setpoints
    stopped: list[str] = field(default_factory=list)  # joints whose setpoints stopped (to log)
    found_without: list[str] = field(default_factory=list)  # joints found unpaired (to log)
    _paired: set[str] = field(default_factory=set)  # joints seen matched
    _kept: OrderedDict[int, Setpoints] = field(default_factory=OrderedDict)
    _newest: dict[str, int] = field(default_factory=dict)  # joint -> newest setpoint stamp
    _pending: deque[tuple[StateSample, float]] = field(default_factory=deque)  # (sample, arrived)
    _released_ns: int = -(2**62)  # newest stamp released

    @property
    def active(self) -> bool:
        """Setpoints have arrived: samples are paired with them."""
        return bool(self._newest)

    @property
    def waiting(self) -> int:
        return len(self._pending)

    def setpoint(self, stamp_ns: int, names: list[str], positions: list[float],
                 velocities: list[float], now_s: float) -> list[Paired]:  # fmt: skip
        """A /joint_setpoints message; the held-back samples it releases, in order."""
        if len(positions) != len(names) or (velocities and len(velocities) != len(names)):
            raise ValueError(
                f"{len(positions)} positions, {len(velocities)} velocities for {len(names)} names"
            )
        values = {
            n: (float(positions[i]), float(velocities[i]) if velocities else 0.0)
            for i, n in enumerate(names)
        }
        for name, (theta_d, theta_d_dot) in values.items():
            if math.isinf(theta_d) or (not math.isnan(theta_d) and not math.isfinite(theta_d_dot)):
                raise ValueError(f"{name}: setpoint {theta_d}, {theta_d_dot} rad/s")
        kept = self._kept.get(stamp_ns)
        if kept is None:
            self._kept[stamp_ns] = values
        else:  # another driver's of the same stamp
            kept.update(values)
        while len(self._kept) > self.max_kept:
            self._kept.popitem(last=False)
        for name in names:
            self._newest[name] = max(self._newest.get(name, stamp_ns), stamp_ns)
            self.unpaired.discard(name)
        return self._release(now_s)

    def sample(self, sample: StateSample, now_s: float) -> list[Paired]:
        """A /joint_states sample; the samples now ready (this one, earlier ones, or none)."""
        if all(n in self.unpaired for n in sample.names) and not self._pending:
            self.unpaired_samples += 1
            self._released_ns = max(self._released_ns, sample.stamp_ns)
            return [Paired(sample, None)]
        self._pending.append((sample, now_s))
        return self._release(now_s)

    def expire(self, now_s: float) -> list[Paired]:
        """The samples that have waited long enough (call it while nothing arrives)."""
        return self._release(now_s) if self._pending else []

    def _release(self, now_s: float) -> list[Paired]:
        ready: list[Paired] = []
        while self._pending:
            head, arrived_s = self._pending[0]
            found = self._kept.get(head.stamp_ns)
            if found is not None and any(n in found for n in head.names):
                self.matched += 1
                self._paired.update(head.names)
                ready.append(Paired(head, found))
            elif all(n in self.unpaired for n in head.names):
                self.unpaired_samples += 1
                ready.append(Paired(head, None))
            elif (
                all(self._newest.get(n, -1) > head.stamp_ns for n in head.names)
                or now_s - arrived_s > self._wait_s(head)
                or len(self._pending) > self.max_pending
            ):
                ready.append(self._without(head))
            else:
                break
            self._pending.popleft()
            self._released_ns = max(self._released_ns, head.stamp_ns)
        self._forget()
        return ready

    def _wait_s(self, sample: StateSample) -> float:
        """A joint known to get setpoints waits ``max_wait_s``; one not seen yet, longer."""
        if any(n in self._paired for n in sample.names):
            return self.max_wait_s
        first = self.expected_wait_s if self.expected else self.first_wait_s
        return max(first, self.max_wait_s)

    def _without(self, head: StateSample) -> Paired:
        """A sample released without its setpoint: lost on the way, sent before this node
        heard the stream, or its joints get none. The first two take the setpoint of the
        nearest stamp (the driver holds a setpoint between commands: its neighbours are the
        best guess; a stale /joint_commands is what this module exists to avoid).

        A joint never matched gets none when no setpoint has named it at or after the sample's
        stamp; one matched before, when none has for ``first_wait_s`` of stamps (its setpoints
        stopped: reported once through :meth:`take_news`)."""
        window_ns = round(self.first_wait_s * 1e9)
        for name in head.names:
            newest = self._newest.get(name)
            if name in self.unpaired:
                continue
            if name not in self._paired and (newest is None or newest < head.stamp_ns):
                self.unpaired.add(name)
                self.found_without.append(name)
            elif name in self._paired and (newest is None or newest < head.stamp_ns - window_ns):
                self.unpaired.add(name)
                self.stopped.append(name)
        nearest = self._nearest(head, window_ns)
        if any(n in self._paired and n not in self.unpaired for n in head.names):
            self.missing += 1
            return Paired(head, nearest, missing=True)
        if nearest is not None:  # before the first setpoint this node heard
            self.before_first += 1
            return Paired(head, nearest)
        self.unpaired_samples += 1
        return Paired(head, None)

    def _nearest(self, head: StateSample, window_ns: int) -> Setpoints | None:
        """The kept setpoints naming the sample's joints nearest its stamp, the latest before it
        first, within ``window_ns``; None without."""
        before: tuple[int, Setpoints] | None = None
        after: tuple[int, Setpoints] | None = None
        for stamp, values in self._kept.items():
            if abs(stamp - head.stamp_ns) > window_ns or not any(n in values for n in head.names):
                continue
            if stamp <= head.stamp_ns and (before is None or stamp > before[0]):
                before = (stamp, values)
            elif stamp > head.stamp_ns and (after is None or stamp < after[0]):
                after = (stamp, values)
        chosen = before or after
        return chosen[1] if chosen else None

    def _forget(self) -> None:
        """Drop setpoints a second (of stamps) older than anything released: their samples
        have gone."""
        limit = self._released_ns - 1_000_000_000
        while self._kept and next(iter(self._kept)) < limit:
            self._kept.popitem(last=False)

    def take_news(self) -> tuple[list[str], list[str]]:
        """(joints found to get no setpoints, joints whose setpoints stopped) since the last
        call: each is news once."""
        news = (self.found_without, self.stopped)
        self.found_without, self.stopped = [], []
        return news

    def reset(self) -> None:
        """Forget the counts (the estimator's ~/reset); what is held back stays held."""
        self.matched = self.missing = self.unpaired_samples = self.before_first = 0
