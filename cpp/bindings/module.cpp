// The thin _core module: one bind_<topic> per C++ folder. Python's emu package
// is the user's front door; nothing here is meant to be called directly.
#include "bind.h"

PYBIND11_MODULE(_core, m) {
  m.doc() = "emu C++ core (use the emu package, not this module)";
  emu::bindings::bind_energy(m);
  emu::bindings::bind_linalg(m);
  emu::bindings::bind_mesh(m);
  emu::bindings::bind_model(m);
  emu::bindings::bind_solvers(m);
  emu::bindings::bind_testing(m);
}
