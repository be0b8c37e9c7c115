"""A contact sheet of a run's frames (shaded, seen from the side):
    python examples/authoring/picture.py elbow/scene.toml elbow_run
writes elbow_run/contact_sheet.png."""
import glob
import json
import os
import sys

import meshio

from emu.app.scenefile import load_scene_file
from emu.io.plots import contact_sheet


def main(scene_file: str, run_dir: str, columns: int = 4) -> str:
    scene = load_scene_file(scene_file).scene
    files = sorted(glob.glob(os.path.join(run_dir, "frame_*.vtu")))
    if not files:
        raise SystemExit(f"no frame_*.vtu in {run_dir}: run `emu run {scene_file} --out {run_dir}` first")
    with open(os.path.join(run_dir, "log.json")) as f:
        log = json.load(f)
    picks = sorted({round(k * (len(files) - 1) / (columns - 1)) for k in range(columns)})
    frames = [meshio.read(files[k]).points for k in picks]
    entries = [log["frames"][k] for k in picks]
    # the log's activations are absolute: shown as fractions of each muscle's maximum
    acts = [{m: a / scene.parts[m].max_activation for m, a in e["activation"].items()} for e in entries]
    titles = [f"t = {e['time']:.2f} s, elbow {e['bone_angles_deg'].get('forearm', 0.0):.0f} deg" for e in entries]
    out = os.path.join(run_dir, "contact_sheet.png")
    contact_sheet(out, scene, frames, titles=titles, activations=acts, view=(1, 2), columns=columns)
    return out


if __name__ == "__main__":
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    print(f"wrote {main(sys.argv[1], sys.argv[2])}")
