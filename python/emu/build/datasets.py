"""The authors' research scenes, downloaded on first use.

The three tetrahedral scenes of the EMU authors' public research code
(``itsvismay/fast_muscles`` on GitHub, MIT licence) are fetched from that
repository at a pinned commit, checked against pinned SHA-256 hashes, cached,
and converted once into a labelled tet mesh that :func:`emu.io.read` and
:func:`emu.io.load_scene` read::

    import emu, emu.datasets
    scene = emu.io.load_scene(emu.datasets.path("simple_joint"), free_bones=["bottom_bone"])

Scenes (:func:`names`):

- ``simple_joint``: a fusiform ``muscle`` between ``top_bone`` and
  ``bottom_bone``, which share an edge (a hinge);
- ``big_muscle``: a fusiform ``muscle`` between ``bone_1`` and ``bone_2``,
  which share no vertex;
- ``realistic_biceps``: an anatomical ``biceps`` from the ``scapula`` to the
  ``forearm``, over the ``humerus`` (elbow hinge, shoulder ball joint);
  7 tets belong to no part in the original files and keep ``part`` = -1;
- ``arm26``: real bone surfaces, the OpenSim arm26 model's humerus and
  forearm (ulna + radius) from ``opensim-org/opensim-models`` (CC BY 3.0, the
  credit in ``CREDITS.txt`` beside the mesh), posed at 90 degrees of elbow
  flexion, with a biceps and a triceps laid along arm26's muscle paths and
  meshed on first use (:mod:`emu.arm26`; needs the mesher, ``pip install
  emu[mesh]``; about 40 s): ``<cache>/arm26/mesh.vtu`` with what ``emu mesh``
  writes beside it, and the posed surfaces with their parts file in
  ``<cache>/arm26/surfaces/``.

The converted scene ``<cache>/<name>/<name>.vtu`` has points (n, 3), one
``tetra`` block (m, 4, 0-based), cell data ``part`` (int32 part id, -1 for
unlabelled tets) and ``fiber`` (m, 3; zero in bone tets); the ``scene.json``
beside it names the parts (id, name, kind ``muscle`` or ``bone``, tet count).
The repository's MIT licence is copied beside them.

Where the files come from, and where they go (environment variables):

- ``EMU_DATA_DIR``: a local copy of the repository's files (the folder that
  holds ``Scripts/gavin_matlab/data/...``); used instead of the network, the
  hashes are still checked. No pooch needed.
- ``EMU_DATA_URL``: the base URL of the repository's files (default the raw
  GitHub URL at the pinned commit); ``http(s)://`` or ``file://``.
- ``EMU_OPENSIM_DIR``, ``EMU_OPENSIM_URL``: the same for arm26's files (a
  copy of the opensim-models files: the folder holding ``Geometry/`` and
  ``Models/Arm26/``).
- ``EMU_CACHE_DIR``: where downloads and converted scenes are kept (default
  pooch's OS cache folder for ``emu``, e.g. ``~/.cache/emu`` on Linux).

Downloading needs ``pooch`` (``pip install pooch``); it is imported only when
a file is actually downloaded or the default cache folder is looked up.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import tempfile
import time
import urllib.parse
import urllib.request

import numpy as np

__all__ = ["names", "path", "fetch", "fetch_main", "cache_dir", "read_dmat", "convert", "source_files",
           "DatasetError", "DownloadError", "HashMismatchError", "UnknownDatasetError",
           "REPOSITORY", "COMMIT", "BASE_URL", "REGISTRY", "OPENSIM_REPOSITORY", "OPENSIM_COMMIT",
           "OPENSIM_REGISTRY"]

REPOSITORY = "itsvismay/fast_muscles"
COMMIT = "116b1308ce9916dceae70561ed0caf568580c4f3"   # branch consistentContact
BASE_URL = f"https://raw.githubusercontent.com/{REPOSITORY}/{COMMIT}/"

_DATA = "Scripts/gavin_matlab/data"
_LICENSE = "LICENSE"

# SHA-256 of every file used, at its path in the repository (computed from the
# repository's files at COMMIT).
REGISTRY = {
    _LICENSE: "83e4dd21429a91fb7cea67a476032a9641425e5355df2e0f589a738b6ec9fd2c",
    f"{_DATA}/big_muscle/bone_1_I.dmat": "64f1efa1e95cda55cb9983a0fb28bd394ecadbb8c2448b95f784d1a4712e4838",
    f"{_DATA}/big_muscle/bone_2_I.dmat": "96d33da2dddec21270aba308ac47e90bd092b950e7a39f9674095b736d8d6e29",
    f"{_DATA}/big_muscle/combined_T.dmat": "5d9e53da0094c629a3950990eba19809ada1077dc2d34aa427a0d6f29f3eb91f",
    f"{_DATA}/big_muscle/combined_V.dmat": "9ae2557712be09550269a49fea983138d98f6aa1ee814fe57eecb53f7de6c789",
    f"{_DATA}/big_muscle/fiber_directions.dmat": "f39a2aaa9299e0126501c1fda284b67680ac873cb556c25e8d17ae42998a83c0",
    f"{_DATA}/big_muscle/muscle_I.dmat": "b0cf5955ca5c3dc8cc2d4f0f256d646a1f7eda1d54bdf03e1ffbe0add20b57bc",
    f"{_DATA}/realistic_biceps/config.json": "f9c348608af5650b6485de22ba84dd0f32c812b61741b7aea5f40046451f1baa",
    f"{_DATA}/realistic_biceps/generated_files/biceps_muscle_indices.dmat":
        "1725c37e0225cf9c3a98125a23ed6374039d240a88891d1b5a79418106e22caa",
    f"{_DATA}/realistic_biceps/generated_files/combined_fiber_directions.dmat":
        "1aafde1430212bab970bcd612581c85c2582f500b635c945292be32ab4ba6cc9",
    f"{_DATA}/realistic_biceps/generated_files/forearm_bone_indices.dmat":
        "a37eb71fee8f40153de4242ed2ceaffb67e84032b6206623d736d7079a1fd862",
    f"{_DATA}/realistic_biceps/generated_files/humerus_bone_indices.dmat":
        "66ca4bf09f1b01a0ca40d998058603f72b637bd435c68b6a849faaf37de25ad5",
    f"{_DATA}/realistic_biceps/generated_files/joint_indices.dmat":
        "4a23aad89c66a574fefe0ad017676387dac314a6ba2f23c77f7f2ae648e12948",
    f"{_DATA}/realistic_biceps/generated_files/scapula_bone_indices.dmat":
        "0970a460a30d9e07892237ff75ad62026fc4fa4ebc775fdc113a2bfb65bebf13",
    f"{_DATA}/realistic_biceps/generated_files/tet_mesh_T.dmat":
        "984e9c9bd0905fa6666b650dee09443a251d74f974e0938db9e5faa69fbf1a3e",
    f"{_DATA}/realistic_biceps/generated_files/tet_mesh_V.dmat":
        "ad69d46374a22eb0548b53455dab8bd57683e0b20b1e7fc56d8e405153e7d630",
    f"{_DATA}/simple_joint/config.json": "6860b1550dbf4c61aec71204d91fe16bcd4295daa141d02554cfc08d193bf3e2",
    f"{_DATA}/simple_joint/generated_files/bottom_bone_bone_indices.dmat":
        "cdbf57467b87bb47828d969687423758dca14b4e20f8b68935d599656d20ac9e",
    f"{_DATA}/simple_joint/generated_files/combined_fiber_directions.dmat":
        "1eb62601b6325f8f57ca7fa2b3d772a4f7871901f546ff9dc9f920e2bb19a019",
    f"{_DATA}/simple_joint/generated_files/joint_indices.dmat":
        "d3f4a5f0968ec9f440e8a9ec7cf28518eb9a2af550705926c8650315edad87c6",
    f"{_DATA}/simple_joint/generated_files/muscle_muscle_indices.dmat":
        "5b8ad41302fe07c520df19e2d2e7c8d1e9a0b5c4f888de68dcad133c43b98ce8",
    f"{_DATA}/simple_joint/generated_files/tet_mesh_T.dmat":
        "b1ce82f7fb9344a20ee768a019e62b6739eae60cb438efd95a71fcdc0ace8549",
    f"{_DATA}/simple_joint/generated_files/tet_mesh_V.dmat":
        "b960127c626165fbf4bef2b632c6347b379ffd2d6b846d7f397eb3e309422bd2",
    f"{_DATA}/simple_joint/generated_files/top_bone_bone_indices.dmat":
        "378d9e752dd59f00be5a6819814bf01926484b11ef46c963d65c94e2af6b793f",
}

# How each scene is put together from its files: vertices, tets, per-tet fibre
# directions, one tet-index list per part (id, name, kind: the ids and names of
# the project's converted scenes), and the files only used to check the result
# (config.json names the muscles and bones; joint_indices.dmat lists the small
# connector tets at the joints, which are bone tets).
_SCENES = {
    "simple_joint": {
        "dir": f"{_DATA}/simple_joint/generated_files",
        "points": "tet_mesh_V.dmat",
        "tets": "tet_mesh_T.dmat",
        "fiber": "combined_fiber_directions.dmat",
        "parts": [(0, "bottom_bone", "bone", "bottom_bone_bone_indices.dmat"),
                  (1, "muscle", "muscle", "muscle_muscle_indices.dmat"),
                  (2, "top_bone", "bone", "top_bone_bone_indices.dmat")],
        "joint_tets": "joint_indices.dmat",
        "config": f"{_DATA}/simple_joint/config.json",
    },
    "big_muscle": {
        "dir": f"{_DATA}/big_muscle",
        "points": "combined_V.dmat",
        "tets": "combined_T.dmat",
        "fiber": "fiber_directions.dmat",
        "parts": [(0, "muscle", "muscle", "muscle_I.dmat"),
                  (1, "bone_1", "bone", "bone_1_I.dmat"),
                  (2, "bone_2", "bone", "bone_2_I.dmat")],
        "joint_tets": None,
        "config": None,
    },
    "realistic_biceps": {
        "dir": f"{_DATA}/realistic_biceps/generated_files",
        "points": "tet_mesh_V.dmat",
        "tets": "tet_mesh_T.dmat",
        "fiber": "combined_fiber_directions.dmat",
        "parts": [(0, "biceps", "muscle", "biceps_muscle_indices.dmat"),
                  (1, "forearm", "bone", "forearm_bone_indices.dmat"),
                  (2, "humerus", "bone", "humerus_bone_indices.dmat"),
                  (3, "scapula", "bone", "scapula_bone_indices.dmat")],
        "joint_tets": "joint_indices.dmat",
        "config": f"{_DATA}/realistic_biceps/config.json",
    },
}


class _Source:
    """A repository the scenes' files come from: pinned commit, SHA-256 per file,
    and the environment variables for a local copy (dir_env) or another base URL
    (url_env)."""

    def __init__(self, key, repository, commit, registry, dir_env, url_env, holds, licence):
        self.key, self.repository, self.commit, self.registry = key, repository, commit, registry
        self.dir_env, self.url_env, self.holds, self.licence = dir_env, url_env, holds, licence
        self.base_url = f"https://raw.githubusercontent.com/{repository}/{commit}/"

    def offline_hint(self):
        return (f"To work offline, set {self.dir_env} to a local copy of the {self.repository} repository's "
                f"files ({self.holds}), or {self.url_env} to another base URL.")


_FAST_MUSCLES = _Source("fast_muscles", REPOSITORY, COMMIT, REGISTRY, "EMU_DATA_DIR", "EMU_DATA_URL",
                        "the folder holding Scripts/gavin_matlab/data/...", "MIT licence")

# The OpenSim models' repository: arm26's bone surfaces and model file (emu.arm26).
OPENSIM_REPOSITORY = "opensim-org/opensim-models"
OPENSIM_COMMIT = "20a888b9655e73fb84963d6e03eee3752cf6074b"
OPENSIM_REGISTRY = {
    "Geometry/arm_r_humerus.vtp": "46496ac6e4c1f8e0c1973ace8f9d4c6e60af34c65e147b13bacca1dbf3d8fe32",
    "Geometry/arm_r_ulna.vtp": "f277b9404b127c1a14f300275a98a95d5282f5394431c9e819426f33e455bffa",
    "Geometry/arm_r_radius.vtp": "04bddb2abaa5ac4de266828137627ece9c72783cc534eb664285ddddbd5468b5",
    "Models/Arm26/arm26.osim": "e2224d0044eb393b05d64926c3fa1682c451a9adc7f510e5517ef9958d3d41b9",
}
_OPENSIM = _Source("opensim-models", OPENSIM_REPOSITORY, OPENSIM_COMMIT, OPENSIM_REGISTRY, "EMU_OPENSIM_DIR",
                   "EMU_OPENSIM_URL", "the folder holding Geometry/ and Models/Arm26/", "CC BY 3.0, credit in CREDITS.txt")
# Scenes built from surfaces (emu.arm26): name -> (source, version of the build; a new version rebuilds)
_BUILT = {"arm26": (_OPENSIM, 1)}


class DatasetError(Exception):
    """A research scene could not be obtained or converted."""


class UnknownDatasetError(DatasetError, ValueError):
    """No scene of that name."""


class DownloadError(DatasetError, OSError):
    """A file could not be downloaded (or read from EMU_DATA_DIR)."""


class HashMismatchError(DatasetError, ValueError):
    """A file's SHA-256 differs from the pinned one."""


# ----------------------------------------------------------------------------- DMAT

def read_dmat(path) -> np.ndarray:
    """Read a libigl DMAT matrix as a (rows, cols) float64 array.

    Text form: a header line ``cols rows``, then rows*cols whitespace-separated
    numbers, column by column. Binary form: a header line ``0 0``, a line
    ``cols rows``, then rows*cols little-endian float64, column-major."""
    path = os.fspath(path)
    with open(path, "rb") as f:
        data = f.read()

    def header(pos):
        end = data.find(b"\n", pos)
        if end < 0:
            raise ValueError(f"{path}: not a DMAT file (no header line 'cols rows')")
        fields = data[pos:end].split()
        try:
            cols, rows = (int(v) for v in fields)
        except ValueError:
            raise ValueError(f"{path}: not a DMAT file (header {data[pos:end][:40]!r}, "
                             "expected 'cols rows')") from None
        if cols < 0 or rows < 0:
            raise ValueError(f"{path}: negative size in DMAT header ({cols} columns, {rows} rows)")
        return cols, rows, end + 1

    cols, rows, pos = header(0)
    if cols == 0 and rows == 0 and pos < len(data):      # binary: a second header, then doubles
        cols, rows, pos = header(pos)
        n = rows * cols
        if len(data) - pos != 8 * n:
            raise ValueError(f"{path}: binary DMAT of {rows} x {cols} needs {8 * n} bytes of data, "
                             f"has {len(data) - pos}")
        values = np.frombuffer(data, dtype="<f8", count=n, offset=pos)
    else:
        try:
            values = np.array(data[pos:].split(), dtype=np.float64)
        except ValueError:
            raise ValueError(f"{path}: text DMAT holds a value that is not a number") from None
        if values.size != rows * cols:
            raise ValueError(f"{path}: text DMAT of {rows} x {cols} needs {rows * cols} values, "
                             f"has {values.size}")
    return np.array(values.reshape(cols, rows).T, dtype=np.float64, order="C")


def _as_index(a, what, upper, path):
    a = np.asarray(a)
    if a.size and (not np.all(np.isfinite(a)) or not np.array_equal(a, np.round(a))):
        raise DatasetError(f"{path}: {what} are not whole numbers")
    idx = a.astype(np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= upper):
        raise DatasetError(f"{path}: {what} out of range [0, {upper})")
    return idx


# ----------------------------------------------------------------------------- conversion

def convert(name, root) -> dict:
    """Convert scene ``name`` from the repository's files under ``root`` (the
    folder holding ``Scripts/gavin_matlab/data``) without checking hashes.

    Returns a dict with ``points`` (n, 3) float64, ``tets`` (m, 4) int64
    (0-based), ``part`` (m,) int32 (-1: in no part), ``fiber`` (m, 3) float64
    and ``parts``: a list of {"id", "name", "kind", "tets"}."""
    spec = _spec(name)
    root = os.fspath(root)
    d = os.path.join(root, *spec["dir"].split("/"))

    def f(rel):
        return os.path.join(d, rel)

    points = read_dmat(f(spec["points"]))
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise DatasetError(f"{f(spec['points'])}: expected finite (n, 3) vertices, got {points.shape}")
    tet_raw = read_dmat(f(spec["tets"]))
    if tet_raw.shape[1] != 4:
        raise DatasetError(f"{f(spec['tets'])}: expected (m, 4) tets, got {tet_raw.shape}")
    tets = _as_index(tet_raw, "tet vertex indices", len(points), f(spec["tets"]))
    m = len(tets)
    fiber = read_dmat(f(spec["fiber"]))
    if fiber.shape != (m, 3):
        raise DatasetError(f"{f(spec['fiber'])}: expected ({m}, 3) fibre directions, got {fiber.shape}")

    part = np.full(m, -1, dtype=np.int32)
    parts = []
    for pid, pname, kind, rel in spec["parts"]:
        idx = _as_index(read_dmat(f(rel)).ravel(), "tet indices", m, f(rel))
        if len(np.unique(idx)) != len(idx):
            raise DatasetError(f"{f(rel)}: tet indices of part '{pname}' repeat")
        clash = part[idx] >= 0
        if clash.any():
            raise DatasetError(f"{f(rel)}: {int(clash.sum())} tets of part '{pname}' are already in another part")
        part[idx] = pid
        parts.append({"id": pid, "name": pname, "kind": kind, "tets": int(len(idx))})

    # cross-checks against the files the conversion does not otherwise use
    if spec["config"] is not None:
        cfg_path = os.path.join(root, *spec["config"].split("/"))
        with open(cfg_path) as fh:
            cfg = json.load(fh)
        want = {(n, "muscle") for n in cfg.get("muscles", {})} | {(n, "bone") for n in cfg.get("bones", {})}
        have = {(p["name"], p["kind"]) for p in parts}
        if want != have:
            raise DatasetError(f"{cfg_path} names parts {sorted(want)}, the conversion made {sorted(have)}")
    if spec["joint_tets"] is not None:
        rel = spec["joint_tets"]
        jt = _as_index(read_dmat(f(rel)).ravel(), "joint tet indices", m, f(rel))
        bone_ids = [p["id"] for p in parts if p["kind"] == "bone"]
        if not np.isin(part[jt], bone_ids).all():
            raise DatasetError(f"{f(rel)}: joint connector tets are not all bone tets")
    return {"points": points, "tets": tets, "part": part, "fiber": fiber, "parts": parts}


def _scene_json(name, conv) -> dict:
    return {
        "mesh": f"{name}.vtu",
        "vertices": int(len(conv["points"])),
        "tets": int(len(conv["tets"])),
        "unassigned_tets": int((conv["part"] < 0).sum()),
        "parts": conv["parts"],
        "source": f"fast_muscles repository (MIT licence), branch consistentContact, commit {COMMIT}, "
                  f"{_spec(name)['dir'].split('/generated_files')[0]}",
    }


def _write_converted(name, conv, out_dir, license_path):
    import meshio

    os.makedirs(out_dir, exist_ok=True)
    vtu = os.path.join(out_dir, f"{name}.vtu")
    meta = os.path.join(out_dir, "scene.json")
    # write beside the target and rename, so an interrupted or concurrent run
    # never leaves a half-written file where a finished one is expected
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".vtu", dir=out_dir)
    os.close(fd)
    try:
        meshio.write_points_cells(tmp, conv["points"], [("tetra", conv["tets"])],
                                  cell_data={"part": [conv["part"]], "fiber": [conv["fiber"]]},
                                  file_format="vtu")
        os.replace(tmp, vtu)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    if license_path is not None:
        shutil.copyfile(license_path, os.path.join(out_dir, "LICENSE"))
    fd, tmp = tempfile.mkstemp(prefix=".scene.", suffix=".json", dir=out_dir)
    with os.fdopen(fd, "w") as fh:
        json.dump(_scene_json(name, conv), fh, indent=2)
        fh.write("\n")
    os.replace(tmp, meta)     # scene.json last: its presence marks a finished conversion
    return vtu


# ----------------------------------------------------------------------------- fetching

def names() -> list:
    """The scene names, sorted."""
    return sorted(list(_SCENES) + list(_BUILT))


def _spec(name):
    if name not in _SCENES:
        raise UnknownDatasetError(f"unknown dataset {name!r}; known datasets: {', '.join(names())}")
    return _SCENES[name]


def _files(name) -> list:
    """The repository paths scene ``name`` needs (LICENSE included)."""
    s = _spec(name)
    rels = [s["points"], s["tets"], s["fiber"]] + [p[3] for p in s["parts"]]
    if s["joint_tets"]:
        rels.append(s["joint_tets"])
    out = [f"{s['dir']}/{r}" for r in rels]
    if s["config"]:
        out.append(s["config"])
    return [_LICENSE] + out


def _import_pooch(why):
    try:
        import pooch
    except ImportError:
        raise ImportError(f"emu.datasets needs pooch {why}: pip install pooch "
                          "(or set EMU_DATA_DIR to a local copy of the fast_muscles repository files "
                          "and EMU_CACHE_DIR to a folder for the converted scenes)") from None
    return pooch


def cache_dir() -> str:
    """Where downloads and converted scenes are kept: $EMU_CACHE_DIR, or pooch's
    OS cache folder for "emu"."""
    env = os.environ.get("EMU_CACHE_DIR")
    if env:
        return os.path.abspath(os.path.expanduser(env))
    pooch = _import_pooch("to find the default cache folder")
    return str(pooch.os_cache("emu"))


def _base_url(source=_FAST_MUSCLES):
    url = os.environ.get(source.url_env) or source.base_url
    return url if url.endswith("/") else url + "/"


def _sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _check_local(root, rel, source=_FAST_MUSCLES):
    p = os.path.join(root, *rel.split("/"))
    if not os.path.isfile(p):
        raise DownloadError(f"{source.dir_env}={root} has no {rel}; {source.dir_env} must be a copy of the "
                            f"{source.repository} repository's files at commit {source.commit} "
                            f"({source.holds})")
    got = _sha256(p)
    if got != source.registry[rel]:
        raise HashMismatchError(f"{p}: SHA-256 {got} differs from the pinned {source.registry[rel]} "
                                f"(the file at commit {source.commit} of {source.repository}); the copy is "
                                "corrupt or from another version")
    return p


class _Downloader:
    """pooch downloader: file:// URLs are copied (pooch knows only http(s),
    ftp, sftp and doi), http(s) goes through pooch's HTTPDownloader with a few
    retries; any failure becomes a DownloadError that names the URL."""

    def __init__(self, pooch, progress, hint):
        self.pooch = pooch
        self.progress = progress
        self.hint = hint

    def __call__(self, url, output_file, pooch_obj, check_only=False):
        if self.progress:
            self.progress(f"downloading {url}")
        scheme = urllib.parse.urlparse(url).scheme
        try:
            if scheme == "file":
                src = urllib.request.url2pathname(urllib.parse.urlparse(url).path)
                if check_only:
                    return os.path.isfile(src)
                with open(src, "rb") as fi, open(output_file, "wb") as fo:
                    shutil.copyfileobj(fi, fo)
                return None
            if scheme not in ("http", "https"):
                raise ValueError(f"unsupported URL scheme {scheme!r} (http, https or file)")
            http = self.pooch.HTTPDownloader(timeout=60)
            for attempt in range(3):
                try:
                    return http(url, output_file, pooch_obj, check_only=check_only)
                except Exception:
                    if attempt == 2:
                        raise
                    time.sleep(1 + attempt)
        except Exception as e:
            raise DownloadError(f"could not download {url} ({type(e).__name__}: {e}). {self.hint}") from e


def _raw_files(name, progress, source=_FAST_MUSCLES, rels=None):
    """Local paths of scene ``name``'s repository files (a dict rel -> path),
    and the folder they are under, downloading what is missing."""
    rels = _files(name) if rels is None else rels
    local = os.environ.get(source.dir_env)
    if local:
        root = os.path.abspath(os.path.expanduser(local))
        if progress:
            progress(f"reading {name} from {source.dir_env}={root}")
        return {rel: _check_local(root, rel, source) for rel in rels}, root
    pooch = _import_pooch("to download the research scenes")
    base = _base_url(source)
    root = os.path.join(cache_dir(), f"{source.key}-{source.commit[:12]}")
    store = pooch.create(path=root, base_url=base, registry=dict(source.registry), retry_if_failed=0)
    downloader = _Downloader(pooch, progress, source.offline_hint())
    logger = pooch.get_logger()
    level = logger.level
    logger.setLevel("WARNING")      # our own progress messages instead of pooch's
    try:
        out = {}
        for rel in rels:
            try:
                out[rel] = store.fetch(rel, downloader=downloader)
            except DatasetError:
                raise
            except ValueError as e:
                if "hash" not in str(e).lower():
                    raise
                raise HashMismatchError(f"{base}{rel}: {e} The pinned hash is that of the file at "
                                        f"commit {source.commit} of {source.repository}.") from None
    finally:
        logger.setLevel(level)
    return out, root


def source_files(name, *, progress=None) -> dict:
    """{relative path: local path} of the source files a built scene is made
    from (``arm26``: the OpenSim model and bone surfaces, from
    EMU_OPENSIM_DIR or downloaded into the cache and checked by hash)."""
    if name not in _BUILT:
        raise ValueError(f"'{name}' is not built from source files (those that are: {', '.join(sorted(_BUILT))})")
    source = _BUILT[name][0]
    return _raw_files(name, progress, source, sorted(source.registry))[0]


def _built(name, progress, force):
    """Scene ``name`` built from surfaces (emu.arm26): its mesh.vtu, building it
    into the cache on first use (or with force); dataset.json, written last,
    marks a finished build of this source commit and build version."""
    from . import arm26

    source, version = _BUILT[name]
    out_dir = os.path.join(cache_dir(), name)
    vtu = os.path.join(out_dir, "mesh.vtu")
    marker = os.path.join(out_dir, "dataset.json")
    stamp = {"source": f"{source.repository} at commit {source.commit}", "build": version}
    if not force and os.path.isfile(vtu) and os.path.isfile(marker):
        try:
            with open(marker) as fh:
                if json.load(fh) == stamp:
                    return vtu
        except (OSError, ValueError):
            pass
    files = source_files(name, progress=progress)
    if os.path.exists(marker):
        os.remove(marker)
    try:
        arm26.build(files, out_dir, progress=progress)
    except ValueError as e:      # AuthoringError included
        raise DatasetError(f"building {name}: {e}") from None
    with open(marker, "w") as fh:
        json.dump(stamp, fh)
    return vtu


def _converted(name):
    out_dir = os.path.join(cache_dir(), name)
    vtu = os.path.join(out_dir, f"{name}.vtu")
    meta = os.path.join(out_dir, "scene.json")
    if os.path.isfile(vtu) and os.path.isfile(meta):
        try:
            with open(meta) as fh:
                if COMMIT in json.load(fh).get("source", ""):
                    return vtu, out_dir
        except (OSError, ValueError):
            pass
    return None, out_dir


def path(name, *, progress=None, force=False) -> str:
    """Path of scene ``name``'s converted ``.vtu`` (a ``scene.json`` beside it),
    fetching and converting it on first use (or always with ``force=True``).
    ``progress``: a callable taking one message string (e.g. ``print``).
    ``arm26`` is built from surfaces instead (:mod:`emu.arm26`): its ``mesh.vtu``."""
    if name in _BUILT:
        return _built(name, progress, force)
    _spec(name)
    vtu, out_dir = _converted(name)
    if vtu is not None and not force:
        return vtu
    files, root = _raw_files(name, progress)
    if progress:
        progress(f"converting {name}")
    conv = convert(name, root)
    return _write_converted(name, conv, out_dir, files[_LICENSE])


def fetch(name=None, *, progress=None, force=False) -> dict:
    """Fetch and convert ahead of use: one scene (a name), several (a list), or
    all (None). Returns {name: path of the converted .vtu}."""
    todo = names() if name is None else [name] if isinstance(name, str) else list(name)
    for n in todo:
        if n not in _BUILT:
            _spec(n)       # every name checked before anything is downloaded
    return {n: path(n, progress=progress, force=force) for n in todo}


def fetch_main(names=None, progress=print) -> int:
    """For the command line (``emu data [NAME...]``): fetch the named scenes
    (all when none), say what was fetched and where; returns an exit status
    (0, or 1 with the error on stderr)."""
    todo = list(names) if names else None
    try:
        paths = fetch(todo, progress=progress)
    except (DatasetError, ImportError) as e:
        print(f"emu data: {e}", file=sys.stderr)
        return 1
    for source in {_BUILT[n][0] if n in _BUILT else _FAST_MUSCLES: None for n in paths}:
        src = os.environ.get(source.dir_env) or _base_url(source)
        progress(f"source: {src} ({source.repository} at {source.commit[:12]}, {source.licence})")
    for n, p in paths.items():
        progress(f"{n}: {p}")
    return 0
