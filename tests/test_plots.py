"""Pictures: the contact sheet shows what is nearest the viewer, from every
view, and default_view looks along a hinge."""
import matplotlib.image
import numpy as np
import pytest

import emu
from emu.io.plots import PART_COLOURS, contact_sheet, default_view

from test_io import _box


def _bone_in_front_of_muscle(depth_axis, sign):
    """A unit bone block and a muscle block behind it (further from a viewer at
    sign x the depth axis), overlapping in the picture: a Scene."""
    bp, bt = _box([0, 0, 0], [1, 1, 1], 2)
    mp, mt = _box([0, 0, 0], [1, 1, 1], 2)
    shift = np.zeros(3)
    shift[depth_axis] = -2.0 * sign       # the muscle two units further away
    mp = mp * [1.5, 1.5, 1.5] - 0.25 + shift   # and larger, so it shows around the bone
    scene = emu.Scene(np.vstack([bp, mp]), np.vstack([bt, mt + len(bp)]), warn=False)
    scene.add_bone("bone", np.arange(len(bt)))
    scene.add_muscle("muscle", len(bt) + np.arange(len(mt)), fibers=[0.0, 0.0, 1.0])
    return scene


@pytest.mark.parametrize("view", [(0, 1), (1, 0), (1, 2), (2, 1), (2, 0), (0, 2)])
def test_the_nearest_part_covers_the_picture_centre(tmp_path, view):
    depth = ({0, 1, 2} - set(view)).pop()
    sign = 1.0 if view in [(0, 1), (1, 2), (2, 0)] else -1.0   # the viewer: right x up
    scene = _bone_in_front_of_muscle(depth, sign)
    path = tmp_path / "sheet.png"
    contact_sheet(path, scene, [scene.points], view=view)
    img = matplotlib.image.imread(path)[:, :, :3]
    h, w = img.shape[:2]
    centre = img[h // 2 - 3:h // 2 + 4, w // 2 - 3:w // 2 + 4].reshape(-1, 3).mean(axis=0)
    # bone is pale beige (red ~ green), a relaxed muscle pink (red well above green)
    bone = np.asarray(PART_COLOURS["bone"])
    assert centre[0] - centre[1] < 0.12, (centre, bone)
    ring = img[h // 2, int(0.2 * w):int(0.8 * w)]
    assert np.any(ring[:, 0] - ring[:, 1] > 0.15)   # the muscle shows beside the bone


def test_default_view_looks_along_the_hinge():
    scene = emu.scenes.arm(1)                       # the elbow hinge's axis
    [j] = [j for j in scene.joints() if j.axis is not None]
    depth = int(np.argmax(np.abs(j.axis)))
    view = default_view(scene)
    assert depth not in view and len(set(view)) == 2
    extent = np.ptp(scene.points, axis=0)
    assert extent[view[1]] >= extent[view[0]]


def test_frame_title_names_the_frame_and_the_first_two_bones():
    from emu.io.plots import frame_title
    assert frame_title(3, 0.5, {"ulna": 12.3, "humerus": -4.0, "scapula": 1.0}) == \
        "frame 3, t = 0.50 s\nulna +12\u00b0, humerus -4\u00b0"
    assert frame_title(0, 0.0, {}) == "frame 0, t = 0.00 s"   # no bones: one line


def test_a_preview_adds_a_view_where_the_motion_leaves_the_picture_plane(tmp_path):
    """motion_views: one view where the frames move within it; a second,
    looking along the first's right axis, where they move along the axis the
    first looks along by more than 5% of the diagonal; contact_sheet draws
    each view's row of frames (twice the height)."""
    from emu.io.plots import motion_views
    s = emu.scenes.fusiform(1, warn=False)
    diag = emu.bbox_diagonal(s.points)
    in_plane = s.points + np.array([0.2 * diag, 0.0, 0.0])
    out_of_plane = s.points + np.array([0.0, 0.0, 0.06 * diag])
    assert motion_views(s, [s.points, in_plane], (0, 1)) == [(0, 1)]
    assert motion_views(s, [s.points, out_of_plane], (0, 1)) == [(0, 1), (2, 1)]
    assert motion_views(s, [s.points + np.array([0.0, 0.0, 0.04 * diag])], (0, 1)) == [(0, 1)]
    one, two = tmp_path / "one.png", tmp_path / "two.png"
    contact_sheet(one, s, [s.points, out_of_plane], view=(0, 1))
    contact_sheet(two, s, [s.points, out_of_plane], views=[(0, 1), (2, 1)])
    h1, h2 = matplotlib.image.imread(one).shape[0], matplotlib.image.imread(two).shape[0]
    assert h2 == 2 * h1
