"""emu.datasets: the DMAT reader, the download / convert / cache path (offline,
through a file:// base URL and through EMU_DATA_DIR), hashes and errors."""
import json
import os
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from emu.build import datasets
from conftest import SHARED_DATA as SHARED
from conftest import SHARED_RAW as RAW


# the same skip as conftest.shared_path / shared_raw, as a marker
needs_shared = pytest.mark.skipif(
    not (RAW / "Scripts").is_dir(),
    reason=f"shared data not found at {RAW}")


@pytest.fixture
def env(monkeypatch, tmp_path):
    """A private cache, no EMU_DATA_DIR / EMU_DATA_URL from the caller."""
    for k in ("EMU_DATA_DIR", "EMU_DATA_URL"):
        monkeypatch.delenv(k, raising=False)
    monkeypatch.setenv("EMU_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path


# ----------------------------------------------------------------------------- DMAT reader

def _binary_dmat(path, a):
    a = np.asarray(a, dtype=np.float64)
    rows, cols = a.shape
    with open(path, "wb") as f:
        f.write(b"0 0\n")
        f.write(f"{cols} {rows}\n".encode())
        for j in range(cols):                      # column-major, little-endian
            for i in range(rows):
                f.write(struct.pack("<d", a[i, j]))


def test_read_dmat_text(tmp_path):
    # libigl's example: m = [1 2 3; 4 5 6] is "3 2" then the values column by column
    p = tmp_path / "m.dmat"
    p.write_bytes(b"3 2\n1 4\n2 5\n3 6\n")
    m = datasets.read_dmat(p)
    assert m.dtype == np.float64 and m.shape == (2, 3)
    np.testing.assert_array_equal(m, [[1, 2, 3], [4, 5, 6]])
    q = tmp_path / "v.dmat"
    q.write_bytes(b"1 3\r\n0.5\r\n-1e-3\r\n7\r\n")
    np.testing.assert_array_equal(datasets.read_dmat(q), [[0.5], [-1e-3], [7]])


def test_read_dmat_binary(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.standard_normal((5, 3))
    p = tmp_path / "a.dmat"
    _binary_dmat(p, a)
    np.testing.assert_array_equal(datasets.read_dmat(p), a)      # bit for bit
    b = np.arange(7.0).reshape(7, 1)
    _binary_dmat(p, b)
    np.testing.assert_array_equal(datasets.read_dmat(p), b)


def test_read_dmat_errors(tmp_path):
    p = tmp_path / "bad.dmat"
    p.write_bytes(b"2 2\n1 2 3\n")
    with pytest.raises(ValueError, match="needs 4 values, has 3"):
        datasets.read_dmat(p)
    p.write_bytes(b"0 0\n1 2\n" + struct.pack("<d", 1.0))
    with pytest.raises(ValueError, match="needs 16 bytes"):
        datasets.read_dmat(p)
    p.write_bytes(b"hello\n")
    with pytest.raises(ValueError, match="not a DMAT file"):
        datasets.read_dmat(p)


@needs_shared
def test_read_dmat_real_files_are_binary():
    v = datasets.read_dmat(RAW / "Scripts/gavin_matlab/data/simple_joint/generated_files/tet_mesh_V.dmat")
    assert v.shape == (2452, 3)


# ----------------------------------------------------------------------------- the whole path

def _assert_same_as_shared(name, vtu):
    import meshio

    a = meshio.read(SHARED / name / f"{name}.vtu")
    b = meshio.read(vtu)
    assert len(b.cells) == 1 and b.cells[0].type == "tetra"
    np.testing.assert_array_equal(b.points, a.points)
    np.testing.assert_array_equal(b.cells[0].data, a.cells[0].data)
    for k in ("part", "fiber"):
        assert b.cell_data[k][0].dtype == a.cell_data[k][0].dtype
        np.testing.assert_array_equal(b.cell_data[k][0], a.cell_data[k][0])
    ja = json.loads((SHARED / name / "scene.json").read_text())
    jb = json.loads((Path(vtu).parent / "scene.json").read_text())
    assert list(jb) == list(ja)
    for k in ja:
        if k != "source":
            assert jb[k] == ja[k], k
    assert datasets.COMMIT in jb["source"]


@needs_shared
def test_download_convert_cache_via_file_url(env, monkeypatch):
    pytest.importorskip("pooch")
    monkeypatch.setenv("EMU_DATA_URL", RAW.as_uri())        # file:///.../raw/fast_muscles
    msgs = []
    authors = ["big_muscle", "realistic_biceps", "simple_joint"]
    paths = datasets.fetch(authors, progress=msgs.append)
    assert sorted(paths) == authors and datasets.names() == ["arm26"] + authors
    assert any(m.startswith("downloading file://") for m in msgs)
    cache = Path(os.environ["EMU_CACHE_DIR"])
    for name, vtu in paths.items():
        assert Path(vtu) == cache / name / f"{name}.vtu"
        assert (cache / name / "LICENSE").is_file()
        _assert_same_as_shared(name, vtu)

    # second use: nothing downloaded or converted
    msgs.clear()
    assert datasets.path("simple_joint", progress=msgs.append) == paths["simple_joint"]
    assert msgs == []

    # emu.io reads it, names and kinds from the scene.json beside it
    import emu.io
    m = emu.io.read(paths["realistic_biceps"])
    assert m.part_names == {0: "biceps", 1: "forearm", 2: "humerus", 3: "scapula"}
    assert m.part_kinds == {0: "muscle", 1: "bone", 2: "bone", 3: "bone"}
    assert int((m.part == -1).sum()) == 7
    scene = emu.io.load_scene(paths["simple_joint"], free_bones=["bottom_bone"], warn=False)
    assert set(scene.parts) == {"bottom_bone", "muscle", "top_bone"}


@needs_shared
def test_data_dir_used_instead_of_network(env, monkeypatch):
    monkeypatch.setenv("EMU_DATA_DIR", str(RAW))
    monkeypatch.setenv("EMU_DATA_URL", "http://127.0.0.1:9/")   # would fail if used
    msgs = []
    vtu = datasets.path("big_muscle", progress=msgs.append)
    assert not any(m.startswith("downloading") for m in msgs)
    _assert_same_as_shared("big_muscle", vtu)
    assert not (Path(os.environ["EMU_CACHE_DIR"]) / f"fast_muscles-{datasets.COMMIT[:12]}").exists()


def _corrupt_copy(tmp_path, rel):
    copy = tmp_path / "fast_muscles"
    shutil.copytree(RAW, copy, copy_function=shutil.copyfile)   # files writable
    for d, _, _ in os.walk(copy):
        os.chmod(d, 0o755)                                       # the shared folders are read-only
    p = copy / rel
    data = bytearray(p.read_bytes())
    data[-1] ^= 0x01
    p.write_bytes(bytes(data))
    return copy


@needs_shared
def test_hash_mismatch_is_an_error(env, monkeypatch):
    pytest.importorskip("pooch")
    rel = "Scripts/gavin_matlab/data/simple_joint/generated_files/tet_mesh_V.dmat"
    copy = _corrupt_copy(env, rel)
    monkeypatch.setenv("EMU_DATA_URL", copy.as_uri())
    with pytest.raises(datasets.HashMismatchError, match="tet_mesh_V.dmat"):
        datasets.path("simple_joint")
    cache = Path(os.environ["EMU_CACHE_DIR"])
    assert not (cache / "simple_joint" / "simple_joint.vtu").exists()
    assert not (cache / f"fast_muscles-{datasets.COMMIT[:12]}" / rel).exists()
    # the same copy through EMU_DATA_DIR
    monkeypatch.setenv("EMU_DATA_DIR", str(copy))
    with pytest.raises(datasets.HashMismatchError, match="differs from the pinned"):
        datasets.path("simple_joint")


def test_unknown_name_lists_the_known_ones(env):
    with pytest.raises(ValueError, match="known datasets: arm26, big_muscle, realistic_biceps, simple_joint"):
        datasets.path("biceps")
    with pytest.raises(datasets.UnknownDatasetError):
        datasets.fetch(["simple_joint", "nope"])      # checked before anything is fetched
    assert not Path(os.environ["EMU_CACHE_DIR"]).exists()


def test_failed_download_names_url_and_offline_fix(env, monkeypatch):
    pytest.importorskip("pooch")
    monkeypatch.setattr(datasets.time, "sleep", lambda s: None)
    monkeypatch.setenv("EMU_DATA_URL", "http://127.0.0.1:9/")     # nothing listens on port 9
    with pytest.raises(datasets.DownloadError) as e:
        datasets.path("big_muscle")
    assert "http://127.0.0.1:9/LICENSE" in str(e.value) and "EMU_DATA_DIR" in str(e.value)
    monkeypatch.setenv("EMU_DATA_URL", (env / "nowhere").as_uri())
    with pytest.raises(datasets.DownloadError, match="nowhere/LICENSE"):
        datasets.path("big_muscle")


def test_data_dir_with_wrong_layout(env, monkeypatch):
    monkeypatch.setenv("EMU_DATA_DIR", str(env))
    with pytest.raises(datasets.DownloadError, match="has no LICENSE.*Scripts/gavin_matlab/data"):
        datasets.path("simple_joint")


@needs_shared
def test_fetch_main(env, monkeypatch, capsys):
    monkeypatch.setenv("EMU_DATA_DIR", str(RAW))
    lines = []
    assert datasets.fetch_main(["simple_joint"], progress=lines.append) == 0
    assert lines[-1] == f"simple_joint: {Path(os.environ['EMU_CACHE_DIR']) / 'simple_joint' / 'simple_joint.vtu'}"
    assert any(datasets.COMMIT[:12] in s for s in lines)
    assert datasets.fetch_main(["nope"], progress=lines.append) == 1
    assert "known datasets" in capsys.readouterr().err


def test_pooch_is_lazy_and_its_absence_is_explained(env, monkeypatch):
    code = "import sys, emu, emu.build.datasets; print('pooch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
    monkeypatch.setitem(sys.modules, "pooch", None)       # import pooch now raises ImportError
    monkeypatch.delenv("EMU_CACHE_DIR")
    with pytest.raises(ImportError, match="pip install pooch"):
        datasets.path("simple_joint")
