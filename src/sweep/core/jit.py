"""How the core kernels are compiled for the CPU: `@kernel`, and where their machine code is cached.

`kernel` is numba's `njit` with the compiled code cached on disk, one compilation per signature of
non-literal types (`Kernel`), without numba's reference-counting runtime (NRT), and with NumPy's
floating-point error model: a division by zero gives inf or NaN, which the integrator's checks
turn into a rejected try (a non-finite stage) or a failure outcome, instead of a ZeroDivisionError
that ends the whole run and loses the scene (a slip onset's bisection can close on a Painleve
pole, where Phi's coefficient is exactly 0: docs/model.md, 'Roll -> slip'). Results where nothing
divides by zero are the same to the bit.

The kernels never allocate (every buffer comes from the caller) and never return arrays, so nothing
in them needs a reference count; with the runtime on, every row view
(`wk[W_YTMP]`, `K[s]`, `cs[CS_SIG:CS_SIG + 3]`) cost a pair of out-of-line incref/decref calls,
and those calls made a right-hand-side evaluation cost three times its arithmetic (measured when
the runtime was switched off; CHANGELOG.md). An allocation added to a kernel now fails to compile instead of
slowing it; tests/test_jit.py checks that no kernel returns an array.

**The cache is keyed by every kernel source at once** (`CoreCacheLocator`). numba's own cache
invalidates a function only when *its own* file changes ("cache invalidation fails to recognize
changes in symbols defined in a different file", numba's caching notes): the cached machine code of
`integrate.run` contains the `contact`, `model` and `dop853` kernels it calls, and after an edit of
model.py alone it went on running the old model. Here the cache of every kernel lives in a folder
named by the SHA-256 of all the sources they are compiled from (`KERNEL_SOURCES`: this package and
outcomes.py, whose codes the kernels return), and that digest is also
each entry's source stamp: any change of any of them compiles everything once, nothing stale is
ever loaded. The folder is `src/sweep/core/__pycache__/numba-<digest>/`, or
`$NUMBA_CACHE_DIR/sweep-core-<digest>/` where NUMBA_CACHE_DIR is set.
"""
from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

from numba.core import caching as _caching
from numba.core import config as _config
from numba.core import types as _types
from numba.core.registry import CPUDispatcher

CPU_OPTIONS = {"cache": True, "_nrt": False, "error_model": "numpy"}

PACKAGE = Path(__file__).resolve().parents[1]


def kernel_sources(package: Path = PACKAGE) -> tuple[Path, ...]:
    """The sources the kernels are compiled from: the core and outcomes.py (their return codes)."""
    return tuple(sorted((package / "core").glob("*.py"))) + (package / "outcomes.py",)


KERNEL_SOURCES = kernel_sources()


def sources_digest(paths=KERNEL_SOURCES, root: Path = PACKAGE) -> str:
    """SHA-256 (hex) of the given source files, their paths relative to root included."""
    h = hashlib.sha256()
    for path in paths:
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


DIGEST = sources_digest()


def cache_dir() -> Path:
    """The folder that holds the compiled kernels of this exact set of sources."""
    if _config.CACHE_DIR:
        return Path(_config.CACHE_DIR) / f"sweep-core-{DIGEST[:16]}"
    return PACKAGE / "core" / "__pycache__" / f"numba-{DIGEST[:16]}"


class CoreCacheLocator:
    """numba cache locator for the functions defined in KERNEL_SOURCES: one folder per DIGEST, and
    DIGEST as every entry's source stamp (see the module docstring). Other functions are left to
    numba's own locators (from_function returns None)."""

    _files = frozenset(str(p) for p in KERNEL_SOURCES)

    def __init__(self, py_func, py_file):
        self._lineno = py_func.__code__.co_firstlineno
        self._path = str(cache_dir())

    @classmethod
    def from_function(cls, py_func, py_file):
        if str(Path(py_file).resolve()) not in cls._files:
            return None
        self = cls(py_func, py_file)
        try:
            self.ensure_cache_path()
        except OSError:
            return None      # not writable: numba's other locators (user-wide cache) take it
        return self

    def ensure_cache_path(self):
        os.makedirs(self._path, exist_ok=True)
        tempfile.TemporaryFile(dir=self._path).close()

    def get_cache_path(self):
        return self._path

    def get_source_stamp(self):
        return DIGEST

    def get_disambiguator(self):
        return str(self._lineno)


def register_locator(impl_class) -> None:
    """Put CoreCacheLocator first among a numba cache implementation's locators (once)."""
    classes = impl_class._locator_classes
    if CoreCacheLocator not in classes:
        classes.insert(0, CoreCacheLocator)


register_locator(_caching.CacheImpl)


class Kernel(CPUDispatcher):
    """numba's dispatcher, compiled once per signature of non-literal types. numba types a constant
    argument at a call site from jitted code (`slip_rates(x, 0.0, ...)`, `tally_step(cs, istats,
    True, 1)`) as a Literal of its value, and compiled one copy of the kernel, with its callees
    linked in again, per value: 25 of the 189 signatures a first `simulate` compiled. Typed
    without its value, the argument is the same number at run time, and the kernel computes the
    same results from it."""

    def get_call_template(self, args, kws):
        return super().get_call_template(tuple(_types.unliteral(a) for a in args),
                                         {k: _types.unliteral(v) for k, v in kws.items()})


def kernel(fn=None, **options):
    """`@kernel` or `@kernel(nogil=True)`: compile fn as numba's `njit` does, with CPU_OPTIONS (plus
    options), as a Kernel (one compilation per signature of non-literal types).

    `@kernel(inline="always")` has numba inline fn into each caller before LLVM sees it: the parts of
    `model.rhs` use it, since LLVM alone kept the larger ones as calls, and a call that returns a
    tuple through memory made a right-hand side ~20 % slower than the one-function version it
    replaced (CHANGELOG.md)."""
    if fn is None:
        return lambda f: kernel(f, **options)
    if _config.DISABLE_JIT:
        return fn
    opts = {**CPU_OPTIONS, **options}
    cache = opts.pop("cache")
    disp = Kernel(py_func=fn, locals={}, targetoptions={"nopython": True, **opts})
    if cache:
        disp.enable_caching()
    return disp
