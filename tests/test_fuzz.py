"""Fuzzing the front door (hypothesis): random shapes, dtypes, NaN / inf,
out-of-range and negative indices, empty arrays, random and truncated files.
Every input either works or raises a Python exception with a message (a
ValueError or TypeError, scene files a SceneFileError); never a crash, a
hang or another exception type."""
from __future__ import annotations

import os
import warnings

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

import emu  # noqa: E402
from emu import SceneFileError, load_scene_file  # noqa: E402

# 60 examples per test in the suite; EMU_FUZZ_EXAMPLES=2000 for a deeper run
FUZZ = settings(max_examples=int(os.environ.get("EMU_FUZZ_EXAMPLES", "60")), deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                        HealthCheck.function_scoped_fixture])
CLEAR = (ValueError, TypeError)

# a valid two-tet mesh to mutate
POINTS = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
TETS = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])


def _clear(e: Exception):
    assert isinstance(e, CLEAR), f"{type(e).__name__}: {e}"
    assert str(e), f"{type(e).__name__} without a message"


floats = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.sampled_from([0.0, 1e300, -1e-300]))
point_arrays = hnp.arrays(dtype=st.sampled_from([np.float64, np.float32, np.int64, np.complex128, np.bool_]),
                          shape=hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=6), elements=None)
tet_arrays = hnp.arrays(dtype=st.sampled_from([np.int64, np.int32, np.uint8, np.float64, np.bool_]),
                        shape=hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=6),
                        elements=None)


@FUZZ
@given(points=point_arrays, tets=tet_arrays)
def test_scene_from_random_arrays(points, tets):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            s = emu.Scene(points, tets)
        except Exception as e:  # noqa: BLE001 - the point of the test
            _clear(e)
            return
    # accepted: then it is a valid mesh
    assert s.points.ndim == 2 and s.points.shape[1] == 3 and np.all(np.isfinite(s.points))
    assert s.tets.ndim == 2 and s.tets.shape[1] == 4 and s.tets.min() >= 0 and s.tets.max() < len(s.points)


@FUZZ
@given(ids=st.lists(st.one_of(st.integers(-5, 5), st.floats(-2, 3), st.just(float("nan"))), min_size=0, max_size=4),
       fibers=st.one_of(st.none(), hnp.arrays(np.float64, st.sampled_from([(3,), (2, 3), (1, 3), (2,), (3, 3)]),
                                              elements=floats)),
       youngs=floats, poisson=floats)
def test_add_muscle_with_random_arguments(ids, fibers, youngs, poisson):
    s = emu.Scene(POINTS, TETS, warn=False)
    try:
        s.add_muscle("m", tets=ids, fibers=fibers, youngs=youngs, poisson=poisson)
    except Exception as e:  # noqa: BLE001
        _clear(e)
        return
    part = s.parts["m"]
    assert set(part.tets.tolist()) <= {0, 1} and len(part.tets) == len(set(ids))
    assert all(float(i) == int(i) for i in ids), f"non-integer tet ids {ids} accepted"
    assert np.isfinite(part.youngs) and part.youngs > 0 and 0 <= part.poisson < 0.5


def test_ids_are_never_truncated():
    # found by the fuzzing below: 0.5 used to become tet 0, True vertex 1
    s = emu.Scene(POINTS, TETS, warn=False)
    with pytest.raises(ValueError, match="whole numbers, got 0.5"):
        s.add_muscle("m", tets=[0.5, 1.0])
    with pytest.raises(ValueError, match="whole numbers, got nan"):
        s.pin([float("nan")])
    with pytest.raises(ValueError, match="integer ids, got an array of bool"):
        s.pin([True, False])
    with pytest.raises(ValueError, match="tets \\(vertex indices\\) must be whole numbers"):
        emu.Scene(POINTS, TETS + 0.25)
    s.add_muscle("m", tets=[0.0, 1.0])   # whole floats are ids
    assert s.parts["m"].tets.tolist() == [0, 1]


@FUZZ
@given(activation=st.dictionaries(st.sampled_from(["m", "x", ""]), floats, max_size=2),
       pins=st.lists(st.integers(-3, 7), min_size=0, max_size=3))
def test_solve_with_random_activation_and_pins(activation, pins):
    s = emu.Scene(POINTS, TETS, warn=False)
    s.add_muscle("m", tets=[0, 1], fibers=[0, 0, 1])
    try:
        s.pin(pins)
        sol = emu.solve(s, activation, method="fem", max_iterations=20)
    except Exception as e:  # noqa: BLE001
        _clear(e)
        return
    assert np.all(np.isfinite(sol.positions))


@FUZZ
@given(data=st.binary(max_size=400), suffix=st.sampled_from([".vtu", ".msh", ".mesh", ".vtk", ".obj", ".xyz"]))
def test_mesh_reader_on_random_bytes(tmp_path_factory, data, suffix):
    path = tmp_path_factory.mktemp("fuzz") / f"mesh{suffix}"
    path.write_bytes(data)
    try:
        emu.io.read(path)
    except Exception as e:  # noqa: BLE001
        _clear(e)


@pytest.fixture(scope="module")
def valid_vtu(tmp_path_factory):
    path = tmp_path_factory.mktemp("valid") / "mesh.vtu"
    emu.io.write(path, POINTS, TETS, cell_data={"part": np.array([0, 0])})
    return path.read_bytes()


@FUZZ
@given(cut=st.floats(0.0, 1.0), flip=st.integers(0, 10**6))
def test_mesh_reader_on_truncated_and_corrupt_files(tmp_path_factory, valid_vtu, cut, flip):
    data = bytearray(valid_vtu[: int(cut * len(valid_vtu))])
    if data and flip % 3 == 0:
        data[flip % len(data)] ^= 0xFF
    path = tmp_path_factory.mktemp("cut") / "mesh.vtu"
    path.write_bytes(bytes(data))
    try:
        emu.io.read(path)
    except Exception as e:  # noqa: BLE001
        _clear(e)


toml_values = st.one_of(st.integers(-10, 10**6), st.floats(allow_nan=False), st.text(max_size=8), st.booleans(),
                        st.lists(st.integers(-3, 3), max_size=3))


@FUZZ
@given(section=st.sampled_from(["scene", "solver", "muscles.belly", "output", "mesh", "bones.b", "x"]),
       key=st.sampled_from(["kind", "resolution", "method", "alpha", "accuracy", "frames", "dt", "youngs",
                            "activation", "path", "vtu", "modes", "threads", "unknown"]),
       value=toml_values)
def test_scene_file_with_random_entries(tmp_path_factory, section, key, value):
    def toml(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, list):
            return "[" + ", ".join(map(str, v)) + "]"
        return repr(v)  # ints; floats as Python writes them (inf is TOML too)
    path = tmp_path_factory.mktemp("toml") / "scene.toml"
    path.write_text(f'pins = ["proximal"]\n\n[mesh.fusiform]\ntets = 300\n\n[{section}]\n{key} = {toml(value)}\n')
    try:
        load_scene_file(path)
    except SceneFileError as e:
        assert str(e)
    except Exception as e:  # noqa: BLE001
        _clear(e)
