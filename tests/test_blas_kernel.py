"""emu.core.blas_kernel: OpenBLAS's kernel checked before the C++ core loads it.
Where OpenBLAS would pick a kernel without AVX2 on a CPU that has AVX2 (a
virtual machine with a masked CPU model), emu sets OPENBLAS_CORETYPE to the
kernel the CPU allows; a user's OPENBLAS_CORETYPE is left alone."""
from __future__ import annotations

import ctypes.util
import json
import os
import subprocess
import sys

import pytest

from emu.core import blas_kernel

AVX512 = {"sse3", "avx", "avx2", "fma", "avx512f", "avx512bw", "avx512vl", "avx512dq", "avx512cd"}


def test_best_kernel_follows_the_instructions():
    assert blas_kernel.best_kernel(AVX512 | {"avx512_bf16"}) == "Cooperlake"
    assert blas_kernel.best_kernel(AVX512) == "SkylakeX"
    assert blas_kernel.best_kernel({"avx", "avx2", "fma"}) == "Haswell"
    assert blas_kernel.best_kernel({"avx"}) == "Sandybridge"
    assert blas_kernel.best_kernel({"sse3"}) is None
    assert blas_kernel.lacks_avx2("Prescott") and blas_kernel.lacks_avx2("Sandybridge")
    assert not blas_kernel.lacks_avx2("Haswell") and not blas_kernel.lacks_avx2("SkylakeX")
    assert not blas_kernel.lacks_avx2("Zen")


@pytest.fixture
def machine(monkeypatch, tmp_path):
    """A pretend AVX-512 machine whose OpenBLAS would pick `asked[0]`; counts the asks."""
    asked = ["Prescott", 0]

    def detect(library):
        asked[1] += 1
        return asked[0]
    monkeypatch.setenv("EMU_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("OPENBLAS_CORETYPE", raising=False)
    monkeypatch.setattr(blas_kernel, "_cpu_flags", lambda: set(AVX512))
    monkeypatch.setattr(blas_kernel, "_detected_kernel", detect)
    monkeypatch.setattr(blas_kernel.ctypes.util, "find_library", lambda name: "/usr/lib/libopenblas.so.0")
    yield asked
    os.environ.pop("OPENBLAS_CORETYPE", None)


def test_an_old_kernel_on_a_new_cpu_is_replaced_before_loading(machine):
    d = blas_kernel.choose()
    assert os.environ["OPENBLAS_CORETYPE"] == "SkylakeX"
    assert d["detected"] == "Prescott" and d["chosen"] == "SkylakeX" and "masked CPU model" in d["why"]
    # asked once per machine: the answer is cached
    del os.environ["OPENBLAS_CORETYPE"]
    blas_kernel.choose()
    assert machine[1] == 1 and os.environ["OPENBLAS_CORETYPE"] == "SkylakeX"


def test_a_right_kernel_or_a_users_choice_is_left_alone(machine, monkeypatch):
    machine[0] = "SkylakeX"
    d = blas_kernel.choose()
    assert "OPENBLAS_CORETYPE" not in os.environ and d["chosen"] is None
    monkeypatch.setenv("OPENBLAS_CORETYPE", "Haswell")
    d = blas_kernel.choose()
    assert os.environ["OPENBLAS_CORETYPE"] == "Haswell" and d["why"] == "OPENBLAS_CORETYPE set by the user"


def _flags():
    with open("/proc/cpuinfo") as f:
        return next(set(line.split(":", 1)[1].split()) for line in f if line.startswith("flags"))


def test_emu_loads_openblas_with_the_kernel_it_chose(tmp_path, monkeypatch):
    """End to end in a fresh process: a cached answer saying OpenBLAS picks
    Prescott here makes emu set the kernel before the core loads, and
    emu.info() reports the kernel OpenBLAS then runs."""
    library = ctypes.util.find_library("openblas")
    flags = _flags()
    want = blas_kernel.best_kernel(flags)
    if library is None or "avx2" not in flags:
        pytest.skip("needs OpenBLAS and an AVX2 CPU (every CI machine has both)")
    monkeypatch.setenv("EMU_CACHE_DIR", str(tmp_path))     # the children's cache, and cache_file's
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    code = "import emu; i = emu.info(); print(i['kernel'])"
    # on its own: OpenBLAS's pick, reported as such
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert "OpenBLAS's own choice" in out.stdout
    # a machine where OpenBLAS would pick Prescott
    path = blas_kernel.cache_file(library, flags)
    with open(path, "w") as f:
        json.dump({"detected": "Prescott"}, f)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.lower().startswith(want.lower()) and f"OPENBLAS_CORETYPE={want}" in out.stdout
