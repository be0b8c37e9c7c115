#pragma once
#include <pybind11/pybind11.h>

namespace emu::bindings {
void bind_energy(pybind11::module_& m);
void bind_linalg(pybind11::module_& m);
void bind_mesh(pybind11::module_& m);
void bind_model(pybind11::module_& m);
void bind_solvers(pybind11::module_& m);
void bind_testing(pybind11::module_& m);  // after bind_solvers
}  // namespace emu::bindings
