// emu/model: the scene as the solvers see it (Model) and one load (LoadCase).
#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "bind.h"
#include "emu/model/model.h"

namespace py = pybind11;

namespace emu::bindings {

void bind_model(py::module_& m) {
  py::class_<Model>(m, "Model")
      .def(py::init<>())
      .def_readwrite("rest", &Model::rest)
      .def_readwrite("tets", &Model::tets)
      .def_readwrite("mu", &Model::mu)
      .def_readwrite("lam", &Model::lambda)
      .def_readwrite("density", &Model::density)
      .def_readwrite("acap_weight", &Model::acap_weight)
      .def_readwrite("fiber", &Model::fiber)
      .def_readwrite("muscle", &Model::muscle)
      .def_readwrite("pinned", &Model::pinned)
      .def_readwrite("num_muscles", &Model::num_muscles)
      .def_readwrite("bone", &Model::bone, "#T movable-bone id per tet, -1 for soft tissue (empty: no bones)")
      .def_readwrite("num_bones", &Model::num_bones)
      .def_readwrite("joint_points", &Model::joint_points)
      .def_readwrite("joint_bones", &Model::joint_bones)
      .def_readwrite("bone_stiffness", &Model::bone_stiffness)
      .def_readwrite("scene_tet", &Model::scene_tet,
                     "#T: the scene's tet of each tet here (empty: the same index); a solver's model "
                     "stores its tets in an order of its own")
      .def_readwrite("num_scene_tets", &Model::num_scene_tets, "tets of the scene (0: #T)")
      .def("validate", &Model::validate);

  py::class_<LoadCase>(m, "LoadCase")
      .def(py::init<>())
      .def_readwrite("activation", &LoadCase::activation)
      .def_readwrite("pin_positions", &LoadCase::pin_positions)
      .def_readwrite("gravity", &LoadCase::gravity)
      .def_readwrite("joint_targets", &LoadCase::joint_targets)
      .def_readwrite("inertia_weight", &LoadCase::inertia_weight,
                     "1 / h_eff^2 of an implicit time step's inertia (0: quasi-static)")
      .def_readwrite("inertia_target", &LoadCase::inertia_target, "#V by 3 predicted positions of the step");
}

}  // namespace emu::bindings
