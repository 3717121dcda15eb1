"""Compiled loops (numba), typed for callers: ``@jit`` compiles on first use and caches the
machine code on disk next to the module; ``@parallel_jit`` also runs ``numba.prange`` loops on
all cores."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

F = TypeVar("F", bound=Callable[..., Any])


def jit(f: F) -> F:
    return cast(F, numba.njit(cache=True, nogil=True)(f))


def parallel_jit(f: F) -> F:
    return cast(F, numba.njit(cache=True, nogil=True, parallel=True)(f))
