"""Whether the mesher gives the same arm26 mesh twice: builds the arm26
scene's parts (emu.arm26, files from EMU_OPENSIM_DIR or the cache) with
emu.author at the given fTetWild thread counts, printing each build's tet
count, a hash of its tets and its time.

    EMU_OPENSIM_DIR=tests/data/opensim-models python bench/studies/mesh_determinism.py 0 0 1 1
"""
from __future__ import annotations

import hashlib
import sys
import time

import numpy as np

from emu.build import arm26
from emu.build.author import author
from emu.build import datasets


def main(threads: list) -> None:
    files = datasets.source_files("arm26")   # the OpenSim files, as emu.arm26 builds from them
    spec = arm26.parts(files)
    for n in threads:
        t0 = time.perf_counter()
        tets = np.ascontiguousarray(author(spec, threads=n).scene.tets)
        digest = hashlib.sha1(tets.tobytes()).hexdigest()[:10]
        print(f"threads {n}: {len(tets)} tets, tets hash {digest}, {time.perf_counter() - t0:.1f} s", flush=True)


if __name__ == "__main__":
    main([int(t) for t in sys.argv[1:]] or [0, 0])
