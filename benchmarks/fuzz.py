"""Bounded mutational fuzzing of what reads untrusted bytes: the bag reader (and salvage), the
CAN decoders of the three protocols, and the estimator's CDR reader.

Each target starts from real inputs (the bags in bags/ and test/data/external_bags, the replies
the simulated devices send, JointState samples) and mutates them: bit flips, interesting
values, length fields overwritten, slices deleted, duplicated or inserted, truncation. What a
target may do with a mutated input:

* bag reader: return data, or raise BagReadError (naming the bag); salvage: return a report;
* CAN decoders: return a sample or None, or raise CanProtocolError;
* CDR reader: return fields, or raise CdrError.

Anything else is a finding: the input is saved under benchmarks/results/fuzz/ with its
traceback, and the run ends with status 1. Each case runs under a time limit (a hang is a
finding too) and the process under an address-space limit (a giant allocation from a mutated
length field raises MemoryError, a finding, instead of taking the machine down).

    python benchmarks/fuzz.py --seconds 60      # per target; `make fuzz` runs this
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import random
import resource
import shutil
import signal
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

from _results import write_results

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from transparency_ros.bag.errors import BagReadError  # noqa: E402
from transparency_ros.bag.reader import joint_series, open_bag  # noqa: E402
from transparency_ros.bag.salvage import salvage  # noqa: E402
from transparency_ros.canbus.errors import CanProtocolError  # noqa: E402
from transparency_ros.canbus.protocol import (  # noqa: E402
    Frame,
    MitProtocol,
    MoteusProtocol,
    ODriveProtocol,
)
from transparency_ros.canbus.sim_device import MitDevice, MoteusDevice, ODriveDevice  # noqa: E402
from transparency_ros.core.actuator_physics import ActuatorPhysics, PhysicsParams  # noqa: E402
from transparency_ros.core.cdr import CdrError, JointStateReader, encode_joint_state  # noqa: E402
from transparency_ros.core.config import get_actuator  # noqa: E402
from transparency_ros.core.driver import ImpedanceCommand  # noqa: E402

CASE_LIMIT_S = 20
MEMORY_LIMIT = 4 << 30
FINDINGS = ROOT / "benchmarks" / "results" / "fuzz"
INTERESTING = (0x00, 0xFF, 0x7F, 0x80, 0x01)


class CaseTimeoutError(Exception):
    pass


def mutate(data: bytes, rng: random.Random) -> bytes:
    out = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        if not out:
            out += rng.randbytes(rng.randint(1, 16))
            continue
        at = rng.randrange(len(out))
        kind = rng.randrange(7)
        if kind == 0:
            out[at] ^= 1 << rng.randrange(8)
        elif kind == 1:
            out[at] = rng.choice(INTERESTING)
        elif kind == 2:  # a length or count field: a plausible-looking u32/u64
            width = rng.choice((4, 8))
            value = rng.choice((0, 1, 0xFFFFFFFF, 1 << 31, rng.getrandbits(width * 8)))
            out[at : at + width] = value.to_bytes(width, "little")
        elif kind == 3:
            del out[at : at + rng.randint(1, 64)]
        elif kind == 4:
            piece = out[at : at + rng.randint(1, 64)]
            where = rng.randrange(len(out))
            out[where:where] = piece
        elif kind == 5:
            out[at:at] = rng.randbytes(rng.randint(1, 16))
        else:
            del out[rng.randint(0, len(out)) :]
    return bytes(out)


# --------------------------------------------------------------------------- targets


def bag_seeds() -> list[Path]:
    files = sorted((ROOT / "bags").rglob("*.mcap"))[:2]
    external = ROOT / "test" / "data" / "external_bags"
    files += sorted(p for p in external.rglob("*") if p.suffix in (".mcap", ".db3"))
    return [p for p in files if p.stat().st_size < 2_000_000]


def bag_case(seed: Path, data: bytes, tmp: Path, rng: random.Random) -> None:
    bag = tmp / "bag"
    shutil.rmtree(tmp, ignore_errors=True)
    bag.mkdir(parents=True)
    (bag / seed.name).write_bytes(data)
    metadata = seed.parent / "metadata.yaml"
    if metadata.exists() and rng.random() < 0.5:  # with the (now wrong) metadata, or without
        text = metadata.read_text()
        (bag / "metadata.yaml").write_text(text if rng.random() < 0.7 else mutate_text(text, rng))
    try:
        with open_bag(bag) as source:
            topics = source.topics
            for topic, info in sorted(topics.items()):
                if info.msgtype == "sensor_msgs/msg/JointState":
                    joint_series(source, topic)
                for i, _ in enumerate(source.messages([topic])):
                    if i >= 200:
                        break
    except BagReadError as err:
        if str(bag) not in str(err):
            raise AssertionError(f"BagReadError without the bag's path: {err}") from err
    salvage(bag, tmp / "out")


def mutate_text(text: str, rng: random.Random) -> str:
    return mutate(text.encode(), rng).decode("utf-8", "replace")


def can_seeds() -> list[tuple[Any, list[Frame]]]:
    """(protocol, frames it should decode) for MIT, ODrive and moteus: the replies their
    simulated devices give to enable and a command."""
    physics = ActuatorPhysics(PhysicsParams.from_actuator(get_actuator("U10DD")))
    pairs = ((MitProtocol(1), MitDevice(1)), (ODriveProtocol(5), ODriveDevice(5)),
             (MoteusProtocol(2), MoteusDevice(2)))  # fmt: skip
    seeds: list[tuple[Any, list[Frame]]] = []
    for protocol, device in pairs:
        frames: list[Frame] = []
        requests = protocol.enable_frames() + protocol.command_frames(
            ImpedanceCommand(0.1, 0.0, 2.0, 0.0, 0.0), None
        )
        for frame in requests:
            frames += device.handle(frame, physics, 0.0)
        seeds.append((protocol, frames or requests))
    return seeds


def can_case(protocol: Any, frame: Frame, data: bytes, rng: random.Random) -> None:
    arb = frame.arbitration_id
    if rng.random() < 0.2:
        arb = rng.getrandbits(29 if rng.random() < 0.3 else 11)
    with contextlib.suppress(CanProtocolError):
        protocol.decode(frame._replace(arbitration_id=arb, data=data[:64]))


def cdr_case(data: bytes, reader: JointStateReader) -> None:
    with contextlib.suppress(CdrError):
        reader(data)


# --------------------------------------------------------------------------- the run


def _alarm(signum: int, frame: Any) -> None:
    raise CaseTimeoutError(f"case took over {CASE_LIMIT_S} s")


def run_target(
    name: str,
    seconds: float,
    case: Callable[[random.Random], tuple[bytes, Callable[[], None], str]],
    rng: random.Random,
) -> dict[str, Any]:
    start, cases = time.monotonic(), 0
    findings: dict[str, list[Any]] = {}  # distinct failure (where) -> [its label, cases]
    while time.monotonic() - start < seconds:
        data, run, suffix = case(rng)
        cases += 1
        signal.alarm(CASE_LIMIT_S)
        try:
            run()
        except Exception as err:  # noqa: BLE001 - every other exception is a finding
            where = traceback.extract_tb(err.__traceback__)[-1]
            key = f"{type(err).__name__} at {Path(where.filename).name}:{where.lineno}"
            if key not in findings:  # the first input of each kind is kept
                digest = hashlib.sha1(data).hexdigest()[:12]
                FINDINGS.mkdir(parents=True, exist_ok=True)
                (FINDINGS / f"{name}-{digest}{suffix}").write_bytes(data)
                (FINDINGS / f"{name}-{digest}.txt").write_text(traceback.format_exc())
                findings[key] = [f"{key} ({name}-{digest}): {str(err)[:120]}", 0]
            findings[key][1] += 1
        finally:
            signal.alarm(0)
    elapsed = time.monotonic() - start
    return {"target": name, "cases": cases, "seconds": round(elapsed, 1),
            "cases_per_s": round(cases / elapsed, 1),
            "findings": [f"{label} [{n} cases]" for label, n in findings.values()]}  # fmt: skip


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="per target (default 60)")
    parser.add_argument("--seed", type=int, default=None, help="random seed (default: time)")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = parser.parse_args()
    seed = args.seed if args.seed is not None else time.time_ns() % 2**32
    rng = random.Random(seed)
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    signal.signal(signal.SIGALRM, _alarm)
    tmp = Path(tempfile.mkdtemp(prefix="fuzz-"))
    seeds = bag_seeds()
    contents = {p: p.read_bytes() for p in seeds}
    protocols = can_seeds()
    reader = JointStateReader()
    samples = [
        encode_joint_state(
            1, 2, "", names, position=[0.1] * len(names), velocity=[0.2] * len(names)
        )
        for names in (["j"], ["a", "b", "c"], [])
    ]

    def bag_input(r: random.Random) -> tuple[bytes, Callable[[], None], str]:
        path = r.choice(seeds)
        data = mutate(contents[path], r)
        return data, lambda: bag_case(path, data, tmp, r), path.suffix

    def can_input(r: random.Random) -> tuple[bytes, Callable[[], None], str]:
        protocol, frames = r.choice(protocols)
        frame = r.choice(frames)
        data = mutate(bytes(frame.data), r)
        return data, lambda: can_case(protocol, frame, data, r), ".can"

    def cdr_input(r: random.Random) -> tuple[bytes, Callable[[], None], str]:
        data = mutate(r.choice(samples), r)
        return data, lambda: cdr_case(data, reader), ".cdr"

    results = []
    try:
        for name, make in (("bag_reader", bag_input), ("can_decoders", can_input),
                           ("cdr_reader", cdr_input)):  # fmt: skip
            print(f"fuzzing {name} for {args.seconds:g} s (seed {seed})", file=sys.stderr)
            results.append(run_target(name, args.seconds, make, rng))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    lines = [
        f"Fuzz run: `python benchmarks/fuzz.py --seconds {args.seconds:g} --seed {seed}`",
        "",
        "| target | seeds | cases | cases/s | findings |",
        "|---|---|---|---|---|",
    ]
    seed_counts = {"bag_reader": len(seeds), "can_decoders": sum(len(f) for _, f in protocols),
                   "cdr_reader": len(samples)}  # fmt: skip
    for r in results:
        lines.append(f"| {r['target']} | {seed_counts[r['target']]} | {r['cases']} | "
                     f"{r['cases_per_s']} | {len(r['findings'])} |")  # fmt: skip
    for r in results:
        lines += [f"- {f}" for f in r["findings"]]
    write_results(args.out, "fuzz", lines, {"seed": seed, "results": results})
    return 1 if any(r["findings"] for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
