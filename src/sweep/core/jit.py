"""How the core kernels are compiled for the CPU: `@kernel`.

`kernel` is numba's `njit` with the compiled code cached on disk and without numba's reference-
counting runtime (NRT). The kernels never allocate (every buffer comes from the caller) and never
return arrays, so nothing in them needs a reference count; with the runtime on, every row view
(`wk[W_YTMP]`, `K[s]`, `cs[CS_SIG:CS_SIG + 3]`) cost a pair of out-of-line incref/decref calls,
and those calls made a right-hand-side evaluation cost three times its arithmetic (docs/
performance.md, 'Cost of the core'). An allocation added to a kernel now fails to compile instead of
slowing it; tests/test_jit.py checks that no kernel returns an array.

numba-cuda compiles the same Python functions as device code (sweep.gpu); it ignores these CPU
options.
"""
from __future__ import annotations

from numba import njit

CPU_OPTIONS = {"cache": True, "_nrt": False}


def kernel(fn=None, **options):
    """`@kernel` or `@kernel(nogil=True)`: compile fn with njit and CPU_OPTIONS (plus options)."""
    opts = {**CPU_OPTIONS, **options}
    if fn is None:
        return njit(**opts)
    return njit(**opts)(fn)
