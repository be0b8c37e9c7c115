"""Shared helpers for the emu test suite: small scenes, the shared research
scenes (skipped the same way everywhere when absent) and an independent numpy
discretisation (G, volumes) that does not go through emu's C++ code."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import emu
from emu.build.procedural import fusiform

ROOT = Path(__file__).resolve().parents[1]


def repo_tool(name: str):
    """The module tools/<name>.py (the repository's scripts are not a package)."""
    spec = importlib.util.spec_from_file_location(f"{name}_tool", ROOT / "tools" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# the authors' research scenes, beside the repository (/work/shared/data)
SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def shared_path(name: str) -> Path:
    """The mesh of the shared research scene ``name`` (SHARED_DATA/<name>/<name>.vtu);
    skips the calling test when it is not there."""
    path = SHARED_DATA / name / f"{name}.vtu"
    if not path.exists():
        pytest.skip(f"shared data not found at {path}")
    return path


# the authors' original files, at their repository paths (emu.datasets reads them offline)
SHARED_RAW = SHARED_DATA / "raw" / "fast_muscles"


def shared_raw() -> Path:
    """The local copy of the authors' repository files; skips the calling test
    when it is not there (the same way as shared_path)."""
    if not (SHARED_RAW / "Scripts").is_dir():
        pytest.skip(f"shared data not found at {SHARED_RAW}")
    return SHARED_RAW


# arm26's files from opensim-models (CC BY 3.0, credit in tests/data/README.md), kept in the
# repository: every machine tests the arm26 path offline
OPENSIM_FILES = Path(__file__).resolve().parent / "data" / "opensim-models"


@pytest.fixture(scope="session", autouse=True)
def research_scenes_offline(tmp_path_factory):
    """emu.datasets (scene files' mesh.dataset, `emu data`) reads the shared copy
    of the authors' files and the repository's copy of arm26's instead of the
    network, into a cache of the session's own; a test that needs the authors'
    files calls shared_raw() first to skip without them."""
    mp = pytest.MonkeyPatch()
    mp.setenv("EMU_OPENSIM_DIR", str(OPENSIM_FILES))
    if (SHARED_RAW / "Scripts").is_dir():
        mp.setenv("EMU_DATA_DIR", str(SHARED_RAW))
    mp.setenv("EMU_CACHE_DIR", str(tmp_path_factory.mktemp("emu_cache")))
    yield
    mp.undo()


def shared_scene(name: str, **load_options):
    """emu.io.load_scene of the shared research scene ``name`` (see shared_path);
    load_options go to load_scene (free_bones, fibers, warn)."""
    return emu.io.load_scene(shared_path(name), **load_options)


def bone_muscle_bone(bone_fraction, r=3):
    """A straight fusiform muscle between two fixed bones, each the end
    ``bone_fraction`` of the length. Returns (scene, mesh, tet centroid z)."""
    m = fusiform(r, tendon_fraction=0.0)
    s = emu.Scene(m.points, m.tets, warn=False)
    z = m.points[m.tets].mean(axis=1)[:, 2]
    lo, hi = bone_fraction * m.length, (1.0 - bone_fraction) * m.length
    s.add_bone("proximal", z < lo)
    s.add_bone("distal", z > hi)
    s.add_muscle("belly", (z >= lo) & (z <= hi))
    return s, m, z


def gap_scene():
    """Two bones that do not touch (a gap at the elbow), an L-shaped muscle
    between them, and a hinge declared at the corner (axis z)."""
    pts, tets, lab = emu.procedural.block_mesh(
        {"upper": [(0, j) for j in range(2, 6)], "lower": [(i, 0) for i in range(2, 6)],
         "muscle": [(1, j) for j in range(1, 5)] + [(i, 1) for i in range(2, 5)]}, 1)
    s = emu.Scene(pts, tets)
    s.add_bone("upper", lab == 0)
    s.add_bone("lower", lab == 1, fixed=False)
    s.add_muscle("muscle", lab == 2)
    return s


PIN_SETS = {"proximal": ("proximal",), "both": ("proximal", "distal"), None: ()}


def bone_chain_scene():
    """A chain: fixed bone "a", movable "b" hinged to it, movable "c" hinged to
    "b" (a joint between two movable bones), muscles "m1", "m2", "m3"."""
    return emu.scenes.chain(1)


def bone_loop_scene():
    """A closed loop of joints: movable "b" and "c" hinged to each other and each
    to the fixed "a"; muscle "m" from a to b. EMU solves it, FEM refuses it."""
    pts, tets, lab = emu.procedural.block_mesh({"a": [(0, 0), (3, 1)], "b": [(1, 1)], "c": [(2, 2)], "m": [(0, 1)]}, 1)
    s = emu.Scene(pts, tets)
    s.add_bone("a", lab == 0)
    s.add_bone("b", lab == 1, fixed=False)
    s.add_bone("c", lab == 2, fixed=False)
    s.add_muscle("m", lab == 3, [1, 1, 0])
    return s


# Small scenes of each kind (a pinned muscle with tendons, a forearm on a hinge,
# a head on a ball joint) with their activation, for tests that compare EMU
# with the converged FEM answer (fixture scene_with_fem).
SMALL_KINDS = {
    "fusiform (pinned, tendons)": (lambda: emu.scenes.fusiform(2, warn=False), {"belly": 5e4}, False),
    "arm (forearm on a hinge)": (lambda: emu.scenes.arm(1), {"flexor": 0.4}, True),
    "neck (head on a ball joint)": (lambda: emu.scenes.neck(1), {"left_front": 0.5}, True),
}


@pytest.fixture(scope="module", params=list(SMALL_KINDS))
def scene_with_fem(request):
    """(scene, activation, normalized, FEM solution to a tight tolerance) for each of SMALL_KINDS."""
    make, act, normalized = SMALL_KINDS[request.param]
    scene = make()
    fem = emu.Solver(scene, "fem", rtol_grad=1e-9).solve(act, normalized=normalized)
    assert fem.converged
    return scene, act, normalized, fem


def small_scene(r=2, pin="proximal", tendon_fraction=0.12, **muscle_kw):
    """The built-in fusiform muscle (emu.scenes.fusiform: tendon caps as a stiff
    tendon part, unless tendon_fraction=0) pinned at its proximal end (pin="both":
    both ends, None: nowhere). Returns (scene, mesh): the mesh (emu.procedural.fusiform)
    for its tendon mask and end faces."""
    s = emu.scenes.fusiform(r, tendon_fraction=tendon_fraction, pins=PIN_SETS[pin], **muscle_kw)
    return s, fusiform(r, tendon_fraction=tendon_fraction)


def rest_geometry(points, tets):
    """Rest volumes (m,) and shape-function gradients b (m, 4, 3), from D_m^-1."""
    p = points[tets]
    Dm = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)  # columns are edges
    vol = np.linalg.det(Dm) / 6.0
    Dinv = np.linalg.inv(Dm)                      # rows are b_1, b_2, b_3
    b = np.empty((len(tets), 4, 3))
    b[:, 1:] = Dinv
    b[:, 0] = -Dinv.sum(axis=1)
    return vol, b


def gradient_operator(points, tets):
    """Dense G (9m x 3n) with vec(F_t) = G_t x, vec column-major
    (F[i, k] at 9t + i + 3k) and x flattened vertex-major (x[v, i] at 3v + i)."""
    import scipy.sparse as sp

    vol, b = rest_geometry(points, tets)
    m, n = len(tets), len(points)
    rows, cols, vals = [], [], []
    for a in range(4):
        for i in range(3):
            for k in range(3):
                rows.append(9 * np.arange(m) + i + 3 * k)
                cols.append(3 * tets[:, a] + i)
                vals.append(b[:, a, k])
    G = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(9 * m, 3 * n))
    return G, vol


def vecF(F):
    """(m, 3, 3) -> (m, 9) column-major rows (the C++ layout)."""
    return np.asarray(F).transpose(0, 2, 1).reshape(-1, 9)


def unvecF(rows):
    return np.asarray(rows).reshape(-1, 3, 3).transpose(0, 2, 1)

