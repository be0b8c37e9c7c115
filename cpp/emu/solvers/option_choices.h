#pragma once
// The spelling of each option that is one of a few choices, the same in C++,
// Python, scene files and the CLI: the bindings take and give these strings,
// and emu.options reads its lists of choices from here.
#include <stdexcept>
#include <string>
#include <vector>

#include "emu/energy/psd_project.h"
#include "emu/solvers/solver_options.h"

namespace emu {

template <class Enum>
struct Choice {
  Enum value;
  const char* name;
};

// Listed in the order the docs show them, the default first.
inline constexpr Choice<EmuStep> kEmuSteps[] = {
    {EmuStep::NewtonKrylov, "newton-krylov"}, {EmuStep::Woodbury, "woodbury"}, {EmuStep::Lbfgs, "lbfgs"}};
inline constexpr Choice<EmuPreconditioner> kEmuPreconditioners[] = {{EmuPreconditioner::ConstantSchur, "constant-schur"},
                                                                    {EmuPreconditioner::Schur, "schur"},
                                                                    {EmuPreconditioner::Woodbury, "woodbury"}};
inline constexpr Choice<EigenFilter> kEigenFilters[] = {{EigenFilter::Clamp, "clamp"}, {EigenFilter::Abs, "abs"}};

template <class Enum, std::size_t N>
std::vector<std::string> choice_names(const Choice<Enum> (&choices)[N]) {
  std::vector<std::string> out;
  for (const auto& c : choices) out.emplace_back(c.name);
  return out;
}

template <class Enum, std::size_t N>
const char* choice_name(const Choice<Enum> (&choices)[N], Enum value) {
  for (const auto& c : choices)
    if (c.value == value) return c.name;
  throw std::logic_error("an option value without a name");
}

// The choice spelled `text`; std::invalid_argument (Python: ValueError) naming
// `option` and its choices otherwise.
template <class Enum, std::size_t N>
Enum parse_choice(const Choice<Enum> (&choices)[N], const std::string& option, const std::string& text) {
  for (const auto& c : choices)
    if (text == c.name) return c.value;
  std::string list;
  for (const auto& c : choices) list += std::string(list.empty() ? "" : ", ") + "'" + c.name + "'";
  throw std::invalid_argument(option + " must be one of " + list + ", got '" + text + "'");
}

}  // namespace emu
