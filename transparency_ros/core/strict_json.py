"""JSON that every parser reads: what the commands print with ``--json`` and write to files.

Python's ``json`` writes ``NaN`` and ``Infinity`` by default, which are not JSON (RFC 8259): jq,
JavaScript's ``JSON.parse``, Go and Rust refuse them. A value that is not a finite number (no
pulses, so no recall; no delay; a bound that does not exist) is written as ``null``. numpy
scalars and arrays, tuples, paths and dataclasses become their JSON counterparts; anything else
is a bug in the caller and raises ``TypeError`` rather than being stringified.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from pathlib import PurePath
from typing import Any, TextIO

import numpy as np


def plain(value: Any) -> Any:
    """``value`` as plain JSON data: non-finite numbers as None."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    elif isinstance(value, PurePath):
        value = str(value)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [plain(v) for v in value]
    if value is None or isinstance(value, bool | int | str):
        return value
    raise TypeError(f"not JSON data: {type(value).__name__} {value!r}")


def dumps(value: Any, indent: int | None = 2) -> str:
    return json.dumps(plain(value), indent=indent, allow_nan=False)


def dump(value: Any, stream: TextIO, indent: int | None = 2) -> None:
    """Write ``value`` and a newline."""
    stream.write(dumps(value, indent) + "\n")


def loads(text: str) -> Any:
    """Parse as strict JSON: NaN, Infinity and -Infinity refused (as other languages do)."""

    def refuse(name: str) -> Any:
        raise ValueError(f"not JSON: {name}")

    return json.loads(text, parse_constant=refuse)
