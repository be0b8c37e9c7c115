"""The example's surfaces, as a modelling tool would export them: one closed
OBJ per part. Run once to remake them (they are committed):
    python examples/authoring/make_surfaces.py
An upper arm held vertically (z up, the shoulder at the top), the forearm
bent forward (+y) at the elbow, and a biceps in front of the humerus from the
humerus' head to the forearm just below the elbow."""
import os

import meshio

from emu.build.shapes import capsule, spindle

HERE = os.path.dirname(os.path.abspath(__file__))
SURFACES = {
    "humerus": capsule([0.0, 0.0, 0.0], [0.0, 0.0, 4.0], 0.35, rings=16, segments=20),
    # the forearm's near end clears the humerus' by 0.15: the elbow hinge joins them
    "forearm": capsule([0.0, 0.0, -0.45], [0.0, 3.5, -0.45], 0.3, rings=16, segments=20),
    # its ends reach into the humerus' head and into the forearm: the attachments
    "biceps": spindle([0.0, 0.2, 3.7], [0.0, 1.6, -0.5], 0.35, rings=20, segments=20, end_radius=0.12),
}

if __name__ == "__main__":
    for name, (V, F) in SURFACES.items():
        meshio.write_points_cells(os.path.join(HERE, f"{name}.obj"), V, [("triangle", F)])
        print(f"wrote {name}.obj: {len(V)} vertices, {len(F)} triangles")
