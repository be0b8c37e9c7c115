"""Figures of a run, rendered off-screen with matplotlib (Agg): a contact sheet
of frames and a plot of joint angle and activation over time.

matplotlib is the one plotting dependency: it renders headless with no GPU or
display, and every user's Python has it or gets it from pip (README)."""
from __future__ import annotations

import numpy as np

from ..core.geometry import bbox_diagonal
from .obj import boundary_faces

__all__ = ["contact_sheet", "motion_views", "mesh_picture", "angle_activation_plot", "default_view", "frame_title",
           "muscle_colour"]

PART_COLOURS = {"bone": (0.93, 0.90, 0.80), "tendon": (0.85, 0.85, 0.95), "muscle": (0.80, 0.35, 0.35)}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# muscles from pale (relaxed) to deep red (fully active)
MUSCLE_RELAXED = np.array([0.93, 0.75, 0.72])
MUSCLE_ACTIVE = np.array([0.70, 0.05, 0.05])


def muscle_colour(a):
    """RGB of a muscle at normalised activation a (scalar or (k,) -> (3,) or (k, 3))."""
    a = np.clip(np.asarray(a, dtype=np.float64), 0.0, 1.0)
    return MUSCLE_RELAXED + a[..., None] * (MUSCLE_ACTIVE - MUSCLE_RELAXED)


def _face_colours(scene, faces_tet, activation_of_tet):
    kinds = np.empty(len(scene.tets), object)
    for p in scene.parts.values():
        kinds[p.tets] = p.kind
    col = np.array([PART_COLOURS[k] for k in kinds[faces_tet]])
    a = activation_of_tet[faces_tet]
    muscle = kinds[faces_tet] == "muscle"
    col[muscle] = muscle_colour(a[muscle])
    return col


def _facing(view) -> tuple:
    """(depth axis, sign): the picture's right and up are the axes ``view``;
    the viewer looks from sign x the depth axis (right x up, right-handed)."""
    depth_axis = ({0, 1, 2} - set(view)).pop()
    return depth_axis, (1.0 if tuple(view) in ((0, 1), (1, 2), (2, 0)) else -1.0)


def _shade(e1, e2, view) -> np.ndarray:
    """Lambert shading of faces (edges e1, e2: (f, 3)) lit from over the
    viewer's upper left, so the surfaces read as 3D: 0.35 (facing away from the
    light) to 1 (facing it)."""
    depth_axis, sign = _facing(view)
    n = np.cross(e1, e2)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    light = np.zeros(3)
    light[depth_axis] = sign   # toward the viewer (the faces kept face it)
    light[view[1]] += 0.6      # from above
    light[view[0]] -= 0.4      # and the left
    light /= np.linalg.norm(light)
    return 0.35 + 0.65 * np.clip(n @ light, 0.0, 1.0)


def default_view(scene, points=None) -> tuple:
    """The picture axes (right, up) that show a scene's motion: looking along
    the first hinge's axis (the bone turns in the picture plane), else along
    the rest mesh's thinnest side; up is the longer of the other two sides."""
    points = scene.points if points is None else np.asarray(points)
    extent = points.max(axis=0) - points.min(axis=0)
    hinges = [j for j in scene.joints() if j.axis is not None] if scene.movable_bones else []
    depth = int(np.argmax(np.abs(hinges[0].axis))) if hinges else int(np.argmin(extent))
    a, b = [k for k in range(3) if k != depth]
    return (a, b) if extent[b] >= extent[a] else (b, a)


def frame_title(frame: int, time: float, bone_angles: dict) -> str:
    """A contact sheet's title for one frame: its number and time, and on a
    second line the first two bones' angles (degrees) where bones move."""
    turn = ", ".join(f"{b} {a:+.0f}\u00b0" for b, a in list(bone_angles.items())[:2])
    return f"frame {frame}, t = {time:.2f} s" + (f"\n{turn}" if turn else "")


def _paint(ax, tri, colours, view):
    """Draw triangles tri (f, 3, 3) with colours (f, 3) on ax: the faces
    towards the viewer, shaded, painted back to front (depth-sorted)."""
    from matplotlib.collections import PolyCollection

    depth_axis, sign = _facing(view)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    nrm = np.cross(e1, e2)[:, depth_axis] * sign
    keep = np.flatnonzero(nrm > 0)
    order = keep[np.argsort(sign * tri[keep, :, depth_axis].mean(axis=1), kind="stable")]
    col = colours[order] * _shade(e1[order], e2[order], view)[:, None]
    ax.add_collection(PolyCollection(tri[order][:, :, list(view)], facecolors=col, edgecolors=(0, 0, 0, 0.06),
                                     linewidths=0.2))


def mesh_picture(path, scene, *, view=None):
    """The labelled mesh as `emu mesh` built it: every part in its own colour
    (a legend names them), joints marked (a cross at the centre, a hinge's axis
    as a line), attachments (vertices a muscle or tendon shares with a bone) as
    dots; two views, ``view`` (default: default_view(scene)) and the one
    turned a quarter about its up axis."""
    plt = _pyplot()
    from matplotlib.patches import Patch

    view = tuple(default_view(scene)) if view is None else tuple(view)
    side = (({0, 1, 2} - set(view)).pop(), view[1])
    faces, faces_tet = boundary_faces(scene.tets, return_tets=True)
    names = list(scene.parts)
    palette = plt.get_cmap("tab10" if len(names) <= 10 else "tab20")
    part_colour = {n: np.array(palette(k % palette.N)[:3]) for k, n in enumerate(names)}
    for n, p in scene.parts.items():   # bones pale, so muscles stand out
        if p.kind == "bone":
            part_colour[n] = 0.45 * part_colour[n] + 0.55 * np.array(PART_COLOURS["bone"])
    tet_colour = np.zeros((len(scene.tets), 3))
    for n, p in scene.parts.items():
        tet_colour[p.tets] = part_colour[n]
    def vertices_of(bones: bool):
        tets = [p.tets for p in scene.parts.values() if (p.kind == "bone") == bones]
        return np.unique(scene.tets[np.concatenate(tets)]) if tets else np.zeros(0, np.int64)
    attach = np.intersect1d(vertices_of(True), vertices_of(False))   # bone vertices a soft part shares
    joints = scene.joints()
    P = scene.points
    extent = (P.max(axis=0) - P.min(axis=0)).max()
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 4.8))
    for ax, v in zip(axes, (view, side)):
        ax.set_axis_off()
        _paint(ax, P[faces], tet_colour[faces_tet], v)
        if len(attach):
            q = P[attach][:, list(v)]
            ax.scatter(q[:, 0], q[:, 1], s=3, color="black", zorder=3, label="attachments")
        for j in joints:
            c = np.asarray(j.centre)
            ax.scatter([c[v[0]]], [c[v[1]]], marker="x", s=60, color="blue", zorder=4)
            if j.axis is not None:
                e = 0.08 * extent * np.asarray(j.axis)
                ax.plot([c[v[0]] - e[v[0]], c[v[0]] + e[v[0]]], [c[v[1]] - e[v[1]], c[v[1]] + e[v[1]]],
                        color="blue", lw=1.5, zorder=4)
            ax.annotate(f"{j.kind} {j.bones[0]}-{j.bones[1]}", (c[v[0]], c[v[1]]), fontsize=7, color="blue",
                        xytext=(4, 4), textcoords="offset points")
        lo, hi = P[:, list(v)].min(axis=0), P[:, list(v)].max(axis=0)
        pad = 0.05 * (hi - lo).max()
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal")
        ax.set_title(f"{'xyz'[v[0]]} right, {'xyz'[v[1]]} up", fontsize=9)
    handles = [Patch(color=part_colour[n], label=f"{n} ({scene.parts[n].kind})") for n in names]
    fig.legend(handles=handles, loc="lower center", ncol=min(4, len(handles)), fontsize=8, frameon=False)
    fig.suptitle(f"{len(scene.tets)} tets; x joints, dots attachments", fontsize=9)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def motion_views(scene, frames, view) -> list:
    """The views a preview needs: ``view``, and a second looking along its
    right axis where the frames move the mesh along the axis ``view`` looks
    along by more than MOTION_OUT_OF_VIEW of the rest mesh's bounding-box
    diagonal (the upper limb's deltoid raises the humerus out of the elbow's
    plane: its 12 degrees move the elbow 9% of the diagonal that way)."""
    rest = scene.points
    motion = np.max([np.abs(np.asarray(f) - rest).max(axis=0) for f in frames], axis=0)
    depth = ({0, 1, 2} - set(view)).pop()
    if motion[depth] > MOTION_OUT_OF_VIEW * bbox_diagonal(rest):
        return [tuple(view), (depth, view[1])]
    return [tuple(view)]


MOTION_OUT_OF_VIEW = 0.05


_AXES = "xyz"


def contact_sheet(path, scene, frames, *, titles=None, activations=None, view=(0, 1), columns=None, views=None):
    """Draw solved frames side by side, looking along the axis not in ``view``.

    frames       list of (n, 3) positions
    columns      pictures per row (default: all in one row up to four, else two rows)
    titles       one string per frame
    activations  one {muscle: normalised activation} per frame (muscle colour)
    view         the picture's (right, up) coordinate axes (default x, y; default_view(scene)
                 picks one that shows the motion); the viewer looks from right x up
    views        several such views, each drawing every frame in rows of its own (e.g.
                 motion_views: a second where the motion leaves the first's plane)
    """
    plt = _pyplot()
    faces, faces_tet = boundary_faces(scene.tets, return_tets=True)
    views = [tuple(view)] if views is None else [tuple(v) for v in views]
    n = len(frames)
    cols = columns or (n if n <= 4 else (n + 1) // 2)
    cols = min(cols, n)
    rows_per_view = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows_per_view * len(views), cols, figsize=(3.2 * cols, 3.2 * rows_per_view * len(views)),
                             squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    muscles = scene.muscles
    for v_index, v in enumerate(views):
        allp = np.concatenate([np.asarray(f)[:, list(v)] for f in frames])
        lo, hi = allp.min(axis=0), allp.max(axis=0)
        pad = 0.05 * (hi - lo).max()
        block = axes[v_index * rows_per_view:(v_index + 1) * rows_per_view].ravel()
        for i in range(n):
            ax = block[i]
            P = np.asarray(frames[i])
            act_tet = np.zeros(len(scene.tets))
            for name, a in (activations[i] if activations else {}).items():
                if name in muscles:
                    act_tet[scene.parts[name].tets] = a
            _paint(ax, P[faces], _face_colours(scene, faces_tet, act_tet), v)
            ax.set_xlim(lo[0] - pad, hi[0] + pad)
            ax.set_ylim(lo[1] - pad, hi[1] + pad)
            ax.set_aspect("equal")
            label = "" if len(views) == 1 else f"\n({_AXES[v[0]]} right, {_AXES[v[1]]} up)"
            if titles or label:
                ax.set_title((titles[i] if titles else "") + label, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def angle_activation_plot(path, times, angles: dict, activations: dict, *, reference: dict | None = None,
                          title: str = ""):
    """Joint angles (degrees) above, activations (normalised) below, against time.

    angles       {label: (frames,) degrees}
    activations  {muscle: (frames,) normalised activation}
    reference    {label: (frames,) degrees} drawn dashed (e.g. the FEM reference)
    """
    plt = _pyplot()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    for label, v in angles.items():
        a1.plot(times, v, "-o", ms=3, label=label)
    for label, v in (reference or {}).items():
        a1.plot(times, v, "--", color="k", lw=1, label=label)
    a1.set_ylabel("joint angle (degrees)")
    a1.axhline(0, color="0.7", lw=0.5)
    a1.legend(fontsize=8)
    for name, v in activations.items():
        a2.plot(times, v, "-", label=name)
    a2.set_ylabel("activation (normalised)")
    a2.set_xlabel("time (s)")
    a2.set_ylim(-0.05, 1.05)
    a2.legend(fontsize=8)
    if title:
        a1.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
