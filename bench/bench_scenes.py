"""The scenes the benchmark scripts share, by name: each a function returning
(scene, activation, normalized). The authors' research scenes come through
emu.datasets (EMU_DATA_DIR for a local copy)."""
from __future__ import annotations

import time
import warnings

import emu


def start_run(threads: int) -> None:
    """The common start of a benchmark run: warnings off (the tables are the
    output), the thread count set, and a header line naming the version, BLAS,
    threads and date of the run."""
    warnings.simplefilter("ignore")
    emu.runtime.set_threads(threads)
    i = emu.info()
    print(f"emu {i['version']}; BLAS {i['config']}; OpenMP threads {threads}; {time.strftime('%Y-%m-%d')}\n")


def _research(name, free_bones=()):
    return emu.io.load_scene(emu.datasets.path(name), free_bones=list(free_bones), warn=False)


SCENES = {
    "fusiform_r3": lambda: (emu.scenes.fusiform(3, warn=False), {"belly": 5e4}, False),
    "fusiform_20k": lambda: (emu.scenes.fusiform(tets=20000, warn=False), {"belly": 5e4}, False),
    "fusiform_80k": lambda: (emu.scenes.fusiform(tets=80000, warn=False), {"belly": 5e4}, False),
    "fusiform_6k": lambda: (emu.scenes.fusiform(tets=6000, warn=False), {"belly": 5e4}, False),
    "fusiform_300k": lambda: (emu.scenes.fusiform(tets=300000, warn=False), {"belly": 5e4}, False),
    "fusiform_600k": lambda: (emu.scenes.fusiform(tets=600000, warn=False), {"belly": 5e4}, False),
    "simple_joint": lambda: (_research("simple_joint"), {"muscle": 1e4}, False),
    "simple_joint_free": lambda: (_research("simple_joint", ["bottom_bone"]), {"muscle": 1e4}, False),
    "big_muscle_free": lambda: (_research("big_muscle", ["bone_2"]), {"muscle": 1e4}, False),
    "big_muscle_isometric": lambda: (_research("big_muscle"), {"muscle": 2e4}, False),
    "arm_r1": lambda: (emu.scenes.arm(1), {"flexor": 0.45}, True),
    "arm_r3": lambda: (emu.scenes.arm(3), {"flexor": 0.45}, True),
    "arm_r5": lambda: (emu.scenes.arm(5), {"flexor": 0.45}, True),
    "arm_r7": lambda: (emu.scenes.arm(7), {"flexor": 0.45}, True),
    "arm_r9": lambda: (emu.scenes.arm(9), {"flexor": 0.45}, True),
    "neck_r2": lambda: (emu.scenes.neck(2), {"left_front": 0.5}, True),
    "realistic_biceps": lambda: (_research("realistic_biceps", ["forearm"]), {"biceps": 2e3}, False),
    # the paper's first figure as a chain: the scapula fixed, humerus (ball joint, a shoulder spring) and
    # forearm (elbow hinge) both moved by the biceps
    "realistic_biceps_chain": lambda: (_chain_biceps(), {"biceps": 2e3}, False),
    "upper_limb_r2": lambda: (emu.anatomy.upper_limb(2), {"biceps": 0.4}, True),
    "leg_r2": lambda: (emu.anatomy.leg(2), {"hamstring": 0.4}, True),
}


def _chain_biceps(shoulder_stiffness=1e4):
    s = _research("realistic_biceps", ["humerus", "forearm"])
    s.parts["humerus"].joint_stiffness = shoulder_stiffness
    return s
