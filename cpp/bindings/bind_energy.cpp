// Element kernels, exposed for finite-difference tests and for users who want
// to evaluate the material model itself. F is a 3x3 array.
#include <pybind11/eigen.h>

#include "bind.h"
#include "emu/energy/fiber.h"
#include "emu/energy/psd_project.h"
#include "emu/energy/stable_neo_hookean.h"

namespace py = pybind11;

namespace emu::bindings {
void bind_energy(py::module_& m) {
  m.def("snh_energy", &snh::energy, py::arg("F"), py::arg("mu"), py::arg("lam"),
        "Stable Neo-Hookean energy density (rest value subtracted)");
  m.def("snh_stress", &snh::stress, py::arg("F"), py::arg("mu"), py::arg("lam"), "dPsi/dF (3x3)");
  m.def("snh_hessian", &snh::hessian, py::arg("F"), py::arg("mu"), py::arg("lam"),
        "d2Psi/dvec(F)^2 (9x9, vec column-major), not projected");
  m.def("fiber_energy", &fiber::energy, py::arg("F"), py::arg("u"), py::arg("a"));
  m.def("fiber_stress", &fiber::stress, py::arg("F"), py::arg("u"), py::arg("a"));
  m.def("fiber_hessian", &fiber::hessian, py::arg("u"), py::arg("a"));
  m.def(
      "psd_project9",
      [](const Mat9& H, bool reflect) { return psd_project<9>(H, reflect ? EigenFilter::Abs : EigenFilter::Clamp); },
      py::arg("H"), py::arg("reflect") = false,
      "PSD projection of a symmetric 9x9 matrix: negative eigenvalues clamped to 0 (or reflected)");
}
}  // namespace emu::bindings
