"""OpenBLAS's kernel, checked before the library loads.

OpenBLAS built with DYNAMIC_ARCH (Debian's) picks its kernels from the CPU's
family and model when it loads. On a virtual machine whose CPU model is
masked it falls back to its oldest x86-64 kernels (Prescott: SSE3), although
the instructions the machine runs (AVX2, AVX-512) are there: FEM Newton ran
2.5x slower on fusiform_20k. OpenBLAS takes the kernel from OPENBLAS_CORETYPE
where that is set, read once, when the library loads; so `choose()` runs
before emu's C++ core (which links OpenBLAS) is imported: it asks OpenBLAS
(once per machine, in a child process, the answer cached) which kernel it
would pick, and where that kernel lacks AVX2 while the CPU has it, sets
OPENBLAS_CORETYPE to the kernel the CPU's instructions allow. A
OPENBLAS_CORETYPE the user set is left alone. `emu.runtime.info()["kernel"]`
says which kernel runs and why.
"""
from __future__ import annotations

import ctypes.util
import json
import os
import subprocess
import sys

__all__ = ["choose", "best_kernel", "lacks_avx2", "cache_file", "decision"]

# OpenBLAS's x86-64 kernels without AVX2, by the names openblas_get_corename gives (lower case)
_PRE_AVX2 = {"prescott", "core2", "penryn", "dunnington", "nehalem", "atom", "sandybridge", "bulldozer",
             "piledriver", "opteron", "opteron_sse3", "barcelona", "bobcat", "nano", "katmai", "coppermine",
             "northwood", "banias", "athlon", "unknown"}
_AVX512 = {"avx512f", "avx512bw", "avx512vl", "avx512dq", "avx512cd"}

# what choose() did in this process: {"detected", "chosen", "why"}
decision: dict = {}


def best_kernel(flags) -> str | None:
    """The OpenBLAS kernel for a CPU with these /proc/cpuinfo flags: Cooperlake
    (AVX-512 with BF16), SkylakeX (AVX-512), Haswell (AVX2 and FMA),
    Sandybridge (AVX), else None (leave OpenBLAS's choice)."""
    flags = set(flags)
    if _AVX512 <= flags:
        return "Cooperlake" if "avx512_bf16" in flags else "SkylakeX"
    if {"avx2", "fma"} <= flags:
        return "Haswell"
    if "avx" in flags:
        return "Sandybridge"
    return None


def lacks_avx2(kernel: str) -> bool:
    """Whether an OpenBLAS kernel (openblas_get_corename's name) predates AVX2."""
    return kernel.strip().lower() in _PRE_AVX2


def _cpu_flags() -> set:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def _detected_kernel(library: str) -> str | None:
    """The kernel OpenBLAS picks on this machine, asked in a child process (so
    this one loads the library only once, after the decision)."""
    code = ("import ctypes, sys; lib = ctypes.CDLL(sys.argv[1]); f = lib.openblas_get_corename; "
            "f.restype = ctypes.c_char_p; print(f().decode())")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    try:
        out = subprocess.run([sys.executable, "-c", code, library], capture_output=True, text=True, timeout=30,
                             env=env)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


def cache_file(library: str, flags) -> str:
    """Where OpenBLAS's pick is kept for this library, CPU and Python (EMU_CACHE_DIR,
    else the user's cache folder, emu/)."""
    import hashlib

    real = os.path.realpath(library) if os.path.isabs(library) else library
    key = hashlib.sha256(f"{real}|{' '.join(sorted(flags))}|{sys.executable}".encode()).hexdigest()[:16]
    base = os.environ.get("EMU_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "emu")
    return os.path.join(base, f"blas-kernel-{key}.json")


def choose() -> dict:
    """Before the C++ core loads: set OPENBLAS_CORETYPE where OpenBLAS would
    pick a kernel older than the CPU's instructions. Returns (and keeps in
    `decision`) {"detected": OpenBLAS's own pick or None, "chosen": the kernel
    set or None, "why": one line}."""
    global decision
    if os.environ.get("OPENBLAS_CORETYPE"):
        decision = {"detected": None, "chosen": None, "why": "OPENBLAS_CORETYPE set by the user"}
        return decision
    flags = _cpu_flags()
    library = ctypes.util.find_library("openblas")
    if not library or not flags or "avx2" not in flags:
        decision = {"detected": None, "chosen": None, "why": "OpenBLAS's own choice"}
        return decision
    path = cache_file(library, flags)
    detected = None
    try:
        with open(path) as f:
            detected = json.load(f)["detected"]
    except (OSError, ValueError, KeyError, TypeError):
        detected = _detected_kernel(library)
        if detected:
            try:
                os.makedirs(os.path.dirname(path), exist_ok=True)
                with open(path, "w") as f:
                    json.dump({"detected": detected, "library": library}, f)
            except OSError:
                pass
    if detected and lacks_avx2(detected) and best_kernel(flags):
        chosen = best_kernel(flags)
        os.environ["OPENBLAS_CORETYPE"] = chosen
        decision = {"detected": detected, "chosen": chosen,
                    "why": f"OpenBLAS detected {detected} on a CPU with AVX2"
                           f"{' and AVX-512' if _AVX512 <= flags else ''} (a masked CPU model?): "
                           f"emu set OPENBLAS_CORETYPE={chosen}"}
    else:
        decision = {"detected": detected, "chosen": None, "why": "OpenBLAS's own choice"}
    return decision
