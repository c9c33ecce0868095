"""CUDA execution of the batch path (`sweep.simulate_batch(..., device="cuda")`).

numba-cuda is imported here only, and only when device="cuda" is asked for: `require_cuda` fails at
once, with the reason, where the package or a GPU is missing. The kernel is one persistent thread per
resident slot: each thread takes the next scene index from an atomic counter when its scene ends
(scenes differ ~100x in cost), copies the scene's inputs into its local arrays, integrates it with
`core.ensemble.solve_scene` (numba-cuda compiles that @njit function and everything it calls, the
whole hybrid integrator and model, as device functions: no second copy of the physics), and writes
the results into the preallocated device arrays. float64 throughout.

Under numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1, used by the tests on machines without a GPU)
the same kernel runs in Python threads; the copies in and out then run as plain Python (their
`py_func`) on the simulator's arrays and `solve_loaded` (which calls `solve_scene`) as its CPU
compilation, on the thread's local arrays grouped as on the GPU (core.ensemble's namedtuples).
"""
from __future__ import annotations

import math
import os

import numpy as np
from numba import float64, int64

from .core.dop853 import N_DENSE
from .core.jit import register_locator
from .core.frequency import FQ_COLS, FQ_LEVEL0
from .core.ensemble import (MAX_LEVELS, N_DERIVED, N_SCRATCH, PEAK_RING, BatchInputs, BatchOutputs, Fits, SceneInputs,
                            load_inputs, solve_loaded, store_outputs)
from .core.layout import (LEVEL_COLS, N_CS, N_KROWS, N_FSTATS, N_ISTATS, N_SETTINGS, N_TRACK, N_WCOLS, N_WORK,
                          PEAK_COLS, SAMPLE_COLS, TRAJ_COLS, Record, Work)
from .core.model import N_FULL, N_PARAMS

# numba-cuda release the lock pins (requirements.lock); named in the error message
NUMBA_CUDA_PIN = "numba-cuda==0.30.4"
# threads per block: the kernel needs many registers per thread, so small blocks fill an SM best
THREADS_PER_BLOCK = 64
# local-array shapes must be literal constants to numba-cuda (an expression in the kernel is not folded)
F_ROWS = 2 * N_DENSE
LEV_COLS = LEVEL_COLS + 1
FQ_ROWS = FQ_LEVEL0 + MAX_LEVELS


class CudaUnavailableError(RuntimeError):
    """device='cuda' was asked for on a machine that cannot run it."""


_kernel = None
# Set by _build_kernel; module globals, not closure variables, so that the kernel has no closure (numba
# can cache it) and the simulator can swap `cuda` for its own module in it.
cuda = None   # numba.cuda once require_cuda has imported it
_load = load_inputs
_store = store_outputs


def require_cuda():
    """numba.cuda, after checking that it can run here; CudaUnavailableError naming the reason."""
    try:
        from numba import cuda
    except ImportError as exc:
        raise CudaUnavailableError(
            f"device='cuda' needs the numba-cuda package ({NUMBA_CUDA_PIN}, pinned in requirements.lock; "
            f"import failed: {exc}); use device='cpu'") from None
    if simulator_enabled():
        return cuda
    try:
        ok = cuda.is_available()
    except Exception as exc:  # a broken driver install raises instead of answering False
        raise CudaUnavailableError(f"device='cuda': the CUDA driver cannot be used here ({exc}); use device='cpu'") \
            from None
    if not ok:
        raise CudaUnavailableError(
            "device='cuda': no CUDA GPU is available on this machine (numba.cuda.is_available() is False: no "
            "NVIDIA GPU or driver); use device='cpu', or set NUMBA_ENABLE_CUDASIM=1 for numba's (slow) simulator")
    return cuda


def simulator_enabled() -> bool:
    """True under numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1)."""
    try:
        from numba.cuda.core import config
        return bool(config.ENABLE_CUDASIM)
    except ImportError:
        return os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")


# a kernel compiled ahead of time (save_prebuilt) that kernel() installs instead of compiling
PREBUILT_ENV = "SWEEP_CUDA_KERNEL"
PREBUILT_FORMAT = 2


def kernel():
    """The batch kernel (built once per process). Where the environment variable SWEEP_CUDA_KERNEL
    names a file written by `save_prebuilt`, its compiled kernel is installed (no compilation)."""
    global _kernel
    if _kernel is None:
        _kernel = _build_kernel(require_cuda())
        path = os.environ.get(PREBUILT_ENV)
        if path and not simulator_enabled():
            install_prebuilt(_kernel, path)
    return _kernel


def kernel_argtypes():
    """The numba types of the batch kernel's arguments, as `run_cuda` passes them (C-contiguous)."""
    from numba import types

    f1, f2, f3 = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1]
    i1, i2 = types.int64[::1], types.int64[:, ::1]
    # order, Y0, P, S, LE, LV, NL, CHI, counter, ISTATS, FSTATS, LEV, YEND, DER
    return (i1, f2, f2, f2, f2, f2, i1, f1, i1, i2, f2, f3, f2, f2)


def save_prebuilt(path, cc: tuple[int, int]) -> dict:
    """Compile the batch kernel for compute capability `cc` on this machine (no GPU needed: NVVM and
    nvJitLink from the requirements-cuda.txt wheels) and write its cubin and launch facts to `path`
    (lzma-compressed pickle of plain values only, readable by another Python), stamped with the core's
    and the kernel's source fingerprint and the numba-cuda version. A GPU machine then runs it at
    once (`install_prebuilt`, or SWEEP_CUDA_KERNEL=path) instead of compiling for minutes. Returns
    {seconds_compile, seconds_link, ptx_bytes, cubin_bytes, entry_name}.

    It answers numba-cuda's device queries with `cc` for the rest of the process (there is no
    device to ask): run it in a process of its own (benchmarks/cuda_compile_offline.py)."""
    import lzma
    import pickle
    import time
    import types as pytypes

    import numba.cuda.codegen as codegen
    import numba.cuda.dispatcher as dispatcher
    from numba import cuda as cuda_module

    cc = tuple(cc)
    # the key under which numba-cuda looks the cubin up on such a device (CUDACodeLibrary._ensure_cc:
    # the architecture-specific target, sm_90a, from compute capability 9.0 on)
    target = (cc[0], cc[1], "a" if cc >= (9, 0) else "")
    # without a GPU, numba-cuda asks the current device for the compute capability: answer with cc
    dispatcher.get_current_device = lambda: pytypes.SimpleNamespace(compute_capability=cc)
    codegen.CUDACodeLibrary._ensure_cc = lambda self, want=None: target if want is None else want
    disp = _build_kernel(cuda_module)
    t0 = time.perf_counter()
    kern = dispatcher._Kernel(disp.py_func, kernel_argtypes(), **disp.targetoptions)
    t1 = time.perf_counter()
    lib = kern._codelibrary
    cubin = lib.get_cubin(cc=target)
    t2 = time.perf_counter()
    if lib._linking_files or lib.needs_cudadevrt or kern.cooperative or kern.extensions:
        raise RuntimeError("the batch kernel links other files, needs cudadevrt, a cooperative launch or "
                           "extensions: save_prebuilt does not carry those")
    blob = {"format": PREBUILT_FORMAT, "fingerprint": _core_fingerprint(), "cc": cc,
            "numba_cuda": _numba_cuda_version(), "target": target, "library_name": lib.name,
            "entry_name": kern.entry_name, "cubin": bytes(getattr(cubin, "code", cubin)),
            "max_registers": lib._max_registers, "nvvm_options": dict(lib._nvvm_options), "lto": lib._lto,
            "debug": kern.debug, "lineinfo": kern.lineinfo}
    tmp = f"{path}.tmp"
    with lzma.open(tmp, "wb", preset=6) as f:
        pickle.dump(blob, f, protocol=4)
    os.replace(tmp, path)
    return {"seconds_compile": t1 - t0, "seconds_link": t2 - t1, "ptx_bytes": len(lib.get_asm_str(cc=target)),
            "cubin_bytes": len(blob["cubin"]), "entry_name": kern.entry_name}


def install_prebuilt(disp, path) -> None:
    """Register the kernel saved by `save_prebuilt` at `path` as `disp`'s specialization for
    run_cuda's argument types on the current GPU; ValueError naming what differs where it was built
    from other sources, another numba-cuda or for another compute capability."""
    import lzma
    import pickle

    try:
        with lzma.open(path, "rb") as f:
            blob = pickle.load(f)
    except (OSError, EOFError, lzma.LZMAError, pickle.UnpicklingError) as exc:
        raise ValueError(f"{PREBUILT_ENV}={path}: cannot read a prebuilt kernel there ({exc}); write one with "
                         f"benchmarks/cuda_compile_offline.py --cc <X.Y> --save-kernel {path}, or unset "
                         f"{PREBUILT_ENV} to compile here") from None
    if not isinstance(blob, dict):
        raise ValueError(f"{PREBUILT_ENV}={path}: not a prebuilt kernel file (save_prebuilt writes a dict)")
    cc = tuple(cuda.get_current_device().compute_capability)
    want = {"format": PREBUILT_FORMAT, "fingerprint": _core_fingerprint(), "cc": cc,
            "numba_cuda": _numba_cuda_version()}
    for key, value in want.items():
        if blob.get(key) != value:
            raise ValueError(f"{PREBUILT_ENV}={path}: prebuilt kernel's {key} is {blob.get(key)!r}, this "
                             f"machine needs {value!r}; rebuild it with benchmarks/cuda_compile_offline.py "
                             f"--cc {cc[0]}.{cc[1]} --save-kernel {path}")
    from numba import types
    from numba.cuda.codegen import CUDACodeLibrary
    from numba.cuda.core.callconv import _MinimalCallHelper
    from numba.cuda.cudadrv.driver import ObjectCode
    from numba.cuda.dispatcher import CUDADispatcher, _Kernel

    # what numba-cuda's own kernel cache restores (_Kernel._rebuild), from plain values
    lib = CUDACodeLibrary._rebuild(
        codegen=None, name=blob["library_name"], entry_name=blob["entry_name"], llvm_strs=[], ptx_cache={},
        cubin_cache={tuple(blob["target"]): ObjectCode.from_cubin(blob["cubin"])}, linkerinfo_cache={},
        max_registers=blob["max_registers"], nvvm_options=blob["nvvm_options"], needs_cudadevrt=False, nrt=False,
        use_cooperative=False, lto=blob["lto"])
    argtypes = kernel_argtypes()
    kern = _Kernel._rebuild(cooperative=False, name=blob["entry_name"], signature=types.void(*argtypes),
                            codelibrary=lib, debug=blob["debug"], lineinfo=blob["lineinfo"],
                            call_helper=_MinimalCallHelper(), extensions=[])
    spec = CUDADispatcher(disp.py_func, targetoptions=disp.targetoptions)
    spec.add_overload(kern, argtypes)
    spec.disable_compile()
    spec._specialized = True
    disp.specializations[cc, argtypes] = spec


def _core_fingerprint() -> str:
    """The core's fingerprint and the kernel's own source (`_build_kernel`, here)."""
    import hashlib
    import inspect

    from .grid import core_fingerprint

    return hashlib.sha256(core_fingerprint().encode() + b"\0" + inspect.getsource(_build_kernel).encode()).hexdigest()


def _numba_cuda_version() -> str:
    from importlib.metadata import version

    return version("numba-cuda")


def _build_kernel(cuda_module):
    global cuda, _load, _store
    cuda = cuda_module
    sim = simulator_enabled()
    if not sim:
        # the kernel's cache keyed by every source it compiles (core.jit.CoreCacheLocator): numba-cuda's
        # own cache, like numba's, would keep it after an edit of the core alone
        try:
            from numba.cuda.core import caching as cuda_caching
            register_locator(cuda_caching.CacheImpl)
        except (ImportError, AttributeError):   # another numba-cuda layout: its own per-file cache
            pass
    # the simulator's arrays are Python objects: there the copies run as plain Python
    _load = load_inputs.py_func if sim else load_inputs
    _store = store_outputs.py_func if sim else store_outputs

    # cache: the first compilation of the whole integrator for the GPU takes minutes (docs/performance.md)
    @cuda.jit(cache=not sim)
    def batch_kernel(order, Y0, P, S, LE, LV, NL, CHI, counter, ISTATS, FSTATS, LEV, YEND, DER):
        inp = SceneInputs(cuda.local.array(N_FULL, float64), cuda.local.array(N_PARAMS, float64),
                          cuda.local.array(N_SETTINGS, float64), cuda.local.array(MAX_LEVELS, float64),
                          cuda.local.array(MAX_LEVELS, float64))
        work = Work(cuda.local.array(N_FULL, float64), cuda.local.array(N_PARAMS, float64),
                    cuda.local.array(N_CS, float64), cuda.local.array((N_WORK, N_WCOLS), float64),
                    cuda.local.array((N_KROWS, N_FULL), float64), cuda.local.array((F_ROWS, N_FULL), float64),
                    cuda.local.array(N_TRACK, float64))
        rec = Record(cuda.local.array(N_ISTATS, int64), cuda.local.array(N_FSTATS, float64),
                     cuda.local.array((MAX_LEVELS, LEV_COLS), float64), cuda.local.array((1, SAMPLE_COLS), float64),
                     cuda.local.array((1, TRAJ_COLS), float64), cuda.local.array((PEAK_RING, PEAK_COLS), float64),
                     cuda.local.array(N_FULL, float64), cuda.local.array((FQ_ROWS, FQ_COLS), float64))
        fits = Fits(cuda.local.array((N_SCRATCH, MAX_LEVELS), float64), cuda.local.array(N_DERIVED, float64))
        batch_in = BatchInputs(Y0, P, S, LE, LV, NL, CHI)
        batch_out = BatchOutputs(ISTATS, FSTATS, LEV, YEND, DER)
        n = order.shape[0]
        while True:
            k = cuda.atomic.add(counter, 0, 1)   # the next scene, whichever thread is free
            if k >= n:
                break
            i = order[k]
            nl, chi = _load(i, batch_in, inp)
            solve_loaded(inp, nl, chi, work, rec, fits)
            _store(i, nl, rec, fits, batch_out)

    return batch_kernel


def launch_shape(cuda, n: int, regs_per_thread: int | None) -> tuple[int, int]:
    """(blocks, threads per block) for n scenes: as many threads as the GPU keeps resident (by the
    kernel's registers per thread) where n fills them; a smaller batch is spread over every
    multiprocessor (one block each, ceil(n / SMs) threads), not packed into a few full blocks: a
    thread's speed is bound by latency and by its warp's divergence, so fewer threads per SM and
    per warp only help (an H100 ran 1000 scenes on 16 of its 132 SMs with full blocks)."""
    tpb = THREADS_PER_BLOCK
    if simulator_enabled():
        return 1, max(1, min(2, n))   # two simulated threads share the scenes: the counter is exercised
    dev = cuda.get_current_device()
    sms = dev.MULTIPROCESSOR_COUNT
    regs = max(regs_per_thread or 255, 1)
    per_sm = min(dev.MAX_THREADS_PER_MULTIPROCESSOR, dev.MAX_REGISTERS_PER_MULTIPROCESSOR // regs)
    blocks_per_sm = max(per_sm // tpb, 1)
    n = max(n, 1)
    if n <= sms * tpb:
        blocks = min(sms, n)
        return blocks, math.ceil(n / blocks)
    return min(sms * blocks_per_sm, math.ceil(n / tpb)), tpb


def run_cuda(order, Y0, P, S, LE, LV, NL, CHI, outputs) -> dict:
    """Run the batch on the GPU; fills `outputs` (ISTATS, FSTATS, LEV, YEND, DER, host arrays) and
    returns launch facts (blocks, threads, registers and local memory per thread, GPU seconds)."""
    import time

    cuda = require_cuda()
    kern = kernel()
    n = int(order.shape[0])
    d_in = [cuda.to_device(np.ascontiguousarray(a)) for a in (order, Y0, P, S, LE, LV, NL, CHI)]
    d_counter = cuda.to_device(np.zeros(1, np.int64))
    d_out = [cuda.to_device(a) for a in outputs]
    regs = local = None
    launch = kern
    if not simulator_enabled():
        # compile for these argument types first: the registers per thread fix the launch shape
        launch = kern.specialize(*d_in, d_counter, *d_out)
        try:
            regs = int(launch.get_regs_per_thread())
            local = int(launch.get_local_mem_per_thread())
        except Exception:   # a numba-cuda without these queries: the figures are reported as unknown
            regs = local = None
    blocks, tpb = launch_shape(cuda, n, regs)
    t0 = time.perf_counter()
    launch[blocks, tpb](*d_in, d_counter, *d_out)
    cuda.synchronize()
    seconds = time.perf_counter() - t0
    for d, h in zip(d_out, outputs):
        d.copy_to_host(h)
    return {"blocks": blocks, "threads_per_block": tpb, "threads": blocks * tpb, "regs_per_thread": regs,
            "local_mem_per_thread": local, "gpu_seconds": seconds}
