"""Compiled loops (numba), typed for callers; the machine code is cached on disk next to the
module after the first compilation.

* ``@jit`` compiles when the module is imported, so compiled functions may call each other
  (numba resolves them at compile time): the drop-test kernel.
* ``@parallel_jit`` likewise, and runs ``numba.prange`` loops on all cores.
* ``@jit_on_first_call`` for a loop that calls no other compiled function: numba is imported
  and the loop compiled only when it first runs, so importing a module that merely has one (the
  bag reader: every node and command that opens a bag) does not pay numba's start-up.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, TypeVar, cast

F = TypeVar("F", bound=Callable[..., Any])


def jit(f: F) -> F:
    import numba  # noqa: PLC0415

    return cast(F, numba.njit(cache=True, nogil=True)(f))


def parallel_jit(f: F) -> F:
    import numba  # noqa: PLC0415

    return cast(F, numba.njit(cache=True, nogil=True, parallel=True)(f))


def jit_on_first_call(f: F) -> F:
    compiled: list[Callable[..., Any]] = []

    @functools.wraps(f)
    def call(*args: Any) -> Any:
        if not compiled:
            compiled.append(jit(f))
        return compiled[0](*args)

    return cast(F, call)
