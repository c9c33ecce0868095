#!/usr/bin/env python3
"""Compile the batch kernel for a GPU architecture without a GPU, and report its resources.

    .venv/bin/pip install -r requirements-cuda.txt          # NVVM, libdevice, NVRTC, ptxas wheels
    .venv/bin/python benchmarks/cuda_compile_offline.py [--cc 9.0] [--ptx out.ptx] [--no-ptxas]
    .venv/bin/python benchmarks/cuda_compile_offline.py --cc 9.0 --save-kernel kernel_sm90.pkl.xz

Checks that numba-cuda compiles the whole integrator (sweep.core.ensemble.solve_scene and every
@njit function below it) as device code of sweep.gpu's kernel, and prints the compile time, the
PTX size and the number of fused multiply-adds NVVM contracted; then, where `ptxas` is found (the
nvidia-cuda-nvcc wheel ships it), the registers, stack frame (local memory) and spills per thread,
and the resident threads per SM that the registers allow. On a machine without a driver, numba-cuda
asks for the current device's compute capability when it compiles a device function; this script
answers with --cc instead (nothing else is patched).

--save-kernel PATH compiles and links the kernel for --cc (numba-cuda's own compile path: NVVM, then
nvJitLink) and saves it with its cubin (`sweep.gpu.save_prebuilt`); on a GPU machine with the same
sources and numba-cuda, `SWEEP_CUDA_KERNEL=PATH` (or `gpu_throughput.py --kernel PATH`) then runs it
without compiling.
"""
from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import time
import types as pytypes
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))


def find_ptxas() -> str | None:
    exe = shutil.which("ptxas")
    if exe:
        return exe
    import site

    for base in site.getsitepackages():
        for p in Path(base, "nvidia").glob("**/bin/ptxas"):
            return str(p)
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cc", default="9.0", help="compute capability (9.0: H100, 8.0: A100)")
    ap.add_argument("--ptx", default=None, help="write the PTX here")
    ap.add_argument("--no-ptxas", action="store_true")
    ap.add_argument("--save-kernel", default=None, metavar="PATH", help="save the compiled kernel and its cubin here")
    args = ap.parse_args(argv)
    cc = tuple(int(x) for x in args.cc.split("."))
    if args.save_kernel:
        from sweep import gpu

        facts = gpu.save_prebuilt(args.save_kernel, cc)
        print(f"numba-cuda typing + NVVM: {facts['seconds_compile']:.0f} s; PTX {facts['ptx_bytes'] / 1e6:.1f} MB; "
              f"link (nvJitLink): {facts['seconds_link']:.0f} s; cubin {facts['cubin_bytes'] / 1e6:.1f} MB")
        print(f"kernel {facts['entry_name'][:80]}... saved to {args.save_kernel} "
              f"({Path(args.save_kernel).stat().st_size / 1e6:.1f} MB)")
        return 0

    from numba import cuda, types
    import numba.cuda.dispatcher as dispatcher

    dispatcher.get_current_device = lambda: pytypes.SimpleNamespace(compute_capability=cc)
    from sweep import gpu

    kern = gpu._build_kernel(cuda)
    sig = types.void(*gpu.kernel_argtypes())
    t0 = time.perf_counter()
    ptx, _ = cuda.compile(kern.py_func, sig, device=False, cc=cc, output="ptx", abi="numba")
    t_nvvm = time.perf_counter() - t0
    print(f"numba-cuda + NVVM: {t_nvvm:.0f} s; PTX {len(ptx) / 1e6:.1f} MB; "
          f"{ptx.count('fma.rn.f64')} fma.rn.f64 (contracted multiply-adds)")
    out = Path(args.ptx) if args.ptx else Path("/tmp") / f"sweep_batch_kernel_sm{cc[0]}{cc[1]}.ptx"
    out.write_text(ptx)
    print(f"PTX written to {out}")
    ptxas = None if args.no_ptxas else find_ptxas()
    if ptxas is None:
        print("ptxas not run (not found, or --no-ptxas): registers and local memory not reported")
        return 0
    t0 = time.perf_counter()
    res = subprocess.run([ptxas, f"-arch=sm_{cc[0]}{cc[1]}", "-v", "-o", str(out.with_suffix(".cubin")), str(out)],
                         capture_output=True, text=True)
    t_ptxas = time.perf_counter() - t0
    log = res.stdout + res.stderr
    if res.returncode != 0:
        print(log[-3000:])
        return 1
    # the kernel's entry: the properties printed after "Compiling entry function"
    entry = log[log.index("Compiling entry function"):]
    regs = int(re.search(r"Used (\d+) registers", entry).group(1))
    stack = int(re.search(r"(\d+) bytes stack frame", entry).group(1))
    spill_st, spill_ld = map(int, re.search(r"(\d+) bytes spill stores, (\d+) bytes spill loads", entry).groups())
    per_sm = min(2048, 65536 // regs)
    print(f"ptxas sm_{cc[0]}{cc[1]}: {t_ptxas:.0f} s; {regs} registers, {stack} B stack frame (local memory), "
          f"{spill_st} B spill stores / {spill_ld} B spill loads per thread")
    print(f"resident threads per SM by registers: {per_sm} ({per_sm // gpu.THREADS_PER_BLOCK} blocks of "
          f"{gpu.THREADS_PER_BLOCK}); on 132 SMs (H100 SXM): {132 * (per_sm // gpu.THREADS_PER_BLOCK) * gpu.THREADS_PER_BLOCK}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
