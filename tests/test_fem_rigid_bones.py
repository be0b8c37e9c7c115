"""FEM's rigid bones against finite differences: the gradient and the bordered
Newton matrix in the solver's reduced unknowns (free soft displacements, then
each movable bone's exponential-map turn and, for a free bone, translation),
for single bones and for chains (a bone jointed to a movable bone turns with it).

E(z) is the energy at increment z from a state x0 (_core.testing.reduced_energy,
which moves the bones by exp([w]_x) R); the solver's own gradient and dense
Hessian at z = 0 (_core.testing.reduced_system) must be its first and second
derivatives, including the rotation's second-order term and the joint spring."""
from __future__ import annotations

import numpy as np
import pytest

import emu
from emu._core import testing
from emu.build.procedural import block_mesh

# bone kinds by what the movable bone touches: an edge of the fixed base (hinge),
# one vertex (ball), nothing but the muscle (free)
SCENES = {
    "hinge": {"base": [(0, 0, 0)], "m": [(1, 0, 0)], "loose": [(1, 1, 0)]},
    "ball": {"base": [(0, 0, 0)], "m": [(1, 0, 0)], "loose": [(1, 1, 1)]},
    "free": {"base": [(0, 0, 0)], "m": [(1, 0, 0)], "loose": [(2, 0, 0)]},
}
DOFS = {"hinge": 1, "ball": 3, "free": 6}
# chains: a second movable bone "tip" jointed to "loose" (an edge: hinge; a
# vertex: ball) and a second muscle "m2" between them
CHAINS = {
    "hinge-hinge": {"base": [(0, 0, 0)], "m": [(1, 0, 0)], "loose": [(1, 1, 0)], "tip": [(2, 2, 0)],
                    "m2": [(2, 1, 0)]},
    "ball-hinge": {"base": [(0, 0, 0)], "m": [(1, 0, 0)], "loose": [(1, 1, 1)], "tip": [(2, 2, 1)],
                   "m2": [(2, 1, 1)]},
    "free-ball": {"base": [(0, 0, 0)], "m": [(1, 0, 0)], "loose": [(2, 0, 0)], "tip": [(3, 1, 1)],
                  "m2": [(3, 0, 0)]},
}
DOFS.update({"hinge-hinge": 2, "ball-hinge": 4, "free-ball": 9})


def scene(kind, stiffness=0.0):
    pts, tets, lab = block_mesh({**SCENES, **CHAINS}[kind], 2)
    s = emu.Scene(pts, tets, warn=False)
    s.add_bone("base", lab == 0)
    s.add_muscle("m", lab == 1, [1.0, 0.3, 0.1])
    s.add_bone("loose", lab == 2, fixed=False, joint_stiffness=stiffness)
    if kind in CHAINS:
        s.add_bone("tip", lab == 3, fixed=False, joint_stiffness=0.7 * stiffness)
        s.add_muscle("m2", lab == 4, [0.2, 1.0, 0.3])
    s.gravity = [0.0, -9.81, 0.0]
    return s


def state(s):
    """A state away from equilibrium with the bones turned: two FEM iterations."""
    act = {m: 0.6 for m in s.muscles}
    solver = emu.Solver(s, "fem", max_iterations=2)
    x0 = solver.solve(act, normalized=True).positions
    load = solver.load_case(act, normalized=True)
    return solver._core, load, np.asarray(x0)


def with_inertia(core, load, x0):
    """load with a time step's inertia (energy/inertia.h) about as stiff as the
    elastic Newton matrix, its predicted positions off x0 at every vertex."""
    _, H0 = testing.reduced_system(core, load, x0, True)
    load.inertia_weight, load.inertia_target = 1.0, x0
    _, H1 = testing.reduced_system(core, load, x0, True)
    per_weight = np.abs(np.diag(np.asarray(H1) - np.asarray(H0))).max()
    assert per_weight > 0   # the term reaches the Newton matrix
    load.inertia_weight = 0.5 * np.abs(np.diag(np.asarray(H0))).max() / per_weight
    load.inertia_target = x0 + 0.05 * np.abs(x0).max() * np.random.default_rng(7).standard_normal(x0.shape)
    return load


@pytest.mark.parametrize("inertia", [False, True])
@pytest.mark.parametrize("kind", ["hinge", "ball", "free", "hinge-hinge", "ball-hinge", "free-ball"])
def test_bone_gradient_and_bordered_hessian_match_finite_differences(kind, inertia):
    # with inertia: the bones' vertices' lumped masses make them rigid bodies
    s = scene(kind, stiffness=0.3)
    core, load, x0 = state(s)
    if inertia:
        load = with_inertia(core, load, x0)
    g, H = testing.reduced_system(core, load, x0, True)
    g, H = np.asarray(g), np.asarray(H)
    n = len(g)
    nd = DOFS[kind]
    assert (n - nd) % 3 == 0 and n - nd > 0   # 3 per free soft vertex, then the bone's
    E = lambda z: testing.reduced_energy(core, load, x0, z)  # noqa: E731
    # the bone rotation moved (not a trivial state)
    assert np.abs(g[-nd:]).max() > 0
    scale = np.abs(x0).max()
    rng = np.random.default_rng(3)
    h = 1e-4 * scale
    # gradient: every bone coordinate and random mixed directions
    dirs = [np.eye(n)[n - nd + i] for i in range(nd)] + [rng.standard_normal(n) for _ in range(4)]
    for v in dirs:
        v = v / np.linalg.norm(v)
        fd = (E(h * v) - E(-h * v)) / (2 * h)
        assert abs(fd - g @ v) <= 1e-6 * np.abs(g).max() + 1e-6 * abs(fd), (kind, fd, g @ v)
    # Hessian: the quadratic form along directions (second differences), and the
    # bone-bone and bone-soft entries by polarisation
    E0 = E(np.zeros(n))
    hh = 1e-3 * scale
    for v in dirs:
        v = v / np.linalg.norm(v)
        fd2 = (E(hh * v) - 2 * E0 + E(-hh * v)) / hh**2
        assert abs(fd2 - v @ H @ v) <= 1e-4 * abs(v @ H @ v) + 1e-7 * np.abs(H).max(), (kind, fd2, v @ H @ v)
    soft = rng.standard_normal(n)
    soft[-nd:] = 0
    soft /= np.linalg.norm(soft)
    for i in range(nd):
        b = np.eye(n)[n - nd + i]
        q = lambda v: (E(hh * v) - 2 * E0 + E(-hh * v)) / hh**2  # noqa: E731
        cross = (q(b + soft) - q(b - soft)) / 4
        assert abs(cross - b @ H @ soft) <= 5e-3 * np.abs(H).max() ** 0.5 * np.abs(H[-nd:]).max() ** 0.5 + \
            2e-3 * abs(b @ H @ soft), (kind, cross, b @ H @ soft)
    # bone-bone entries (a chain's turns of one bone about another's) by polarisation
    for i in range(nd):
        for j in range(i + 1, nd):
            bi, bj = np.eye(n)[n - nd + i], np.eye(n)[n - nd + j]
            q = lambda v: (E(hh * v) - 2 * E0 + E(-hh * v)) / hh**2  # noqa: E731
            cross = (q(bi + bj) - q(bi - bj)) / 4
            assert abs(cross - H[n - nd + i, n - nd + j]) <= 2e-4 * np.abs(H[-nd:, -nd:]).max(), \
                (kind, i, j, cross, H[n - nd + i, n - nd + j])
    assert np.abs(H - H.T).max() <= 1e-10 * np.abs(H).max()


@pytest.mark.parametrize("kind", ["hinge", "ball", "free", "ball-hinge", "free-ball"])
def test_filtered_bordered_hessian_is_positive_semidefinite(kind):
    s = scene(kind)
    core, load, x0 = state(s)
    _, Hf = testing.reduced_system(core, load, x0, False)
    Hf = np.asarray(Hf)
    w = np.linalg.eigvalsh(0.5 * (Hf + Hf.T))
    assert w.min() >= -1e-9 * w.max()
    # and it differs from the exact one where element Hessians are indefinite or the rotation term is
    _, He = testing.reduced_system(core, load, x0, True)
    assert np.abs(Hf - np.asarray(He)).max() > 0


def test_reduced_energy_checks_its_input():
    s = scene("hinge")
    core, load, x0 = state(s)
    with pytest.raises(ValueError, match="entries"):
        testing.reduced_energy(core, load, x0, np.zeros(3))
