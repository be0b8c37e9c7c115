"""Files in and out: tet meshes through meshio (``mesh``), solved frames and
ParaView series (``vtk``), OBJ surfaces for Blender (``obj``) and the PNG
figures of a run (``plots``, imported on its own: ``emu.io.plots``) and USD
stages (``usd``: write_usd, needs the usd-core extra)."""
from .mesh import TetMesh, load_scene, read, write
from .obj import boundary_faces, part_groups, write_obj
from .vtk import tet_activation, write_pvd, write_solution


def write_usd(path, scene, frames, **kw):
    """Solved frames as one animated USD stage (emu.io.usd.write_usd; needs usd-core)."""
    from .usd import write_usd as _write_usd

    return _write_usd(path, scene, frames, **kw)


__all__ = ["TetMesh", "read", "write", "load_scene", "write_solution", "write_pvd", "tet_activation",
           "boundary_faces", "write_obj", "part_groups", "write_usd"]
