#include "emu/model/model.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace emu {
namespace {
[[noreturn]] void fail(const std::string& s) { throw std::invalid_argument(s); }

template <class M>
void check_finite(const M& a, const char* what) {
  if (!a.allFinite()) fail(std::string(what) + " contains NaN or infinite values");
}
}  // namespace

void Model::validate() const {
  const Eigen::Index n = rest.rows(), m = tets.rows();
  if (n == 0 || m == 0) fail("the model has no vertices or no tets");
  check_finite(rest, "rest positions");
  if (tets.minCoeff() < 0 || tets.maxCoeff() >= n) {
    std::ostringstream s;
    s << "tet indices must lie in [0, " << n << "); got range [" << tets.minCoeff() << ", "
      << tets.maxCoeff() << "]";
    fail(s.str());
  }
  auto need = [&](Eigen::Index rows, const char* what) {
    if (rows != m) {
      std::ostringstream s;
      s << what << " has " << rows << " entries, expected one per tet (" << m << ")";
      fail(s.str());
    }
  };
  need(mu.size(), "mu");
  need(lambda.size(), "lambda");
  need(density.size(), "density");
  need(acap_weight.size(), "acap_weight");
  need(fiber.rows(), "fiber");
  need(muscle.size(), "muscle");
  check_finite(mu, "mu");
  check_finite(lambda, "lambda");
  check_finite(fiber, "fiber");
  check_finite(density, "density");
  check_finite(acap_weight, "acap_weight");
  if ((mu.array() <= 0).any() || (lambda.array() <= 0).any())
    fail("Lame parameters must be positive (Poisson ratio in (0, 0.5))");
  if ((acap_weight.array() <= 0).any()) fail("ACAP weights must be positive");
  if (muscle.size() && (muscle.maxCoeff() >= num_muscles || muscle.minCoeff() < -1))
    fail("muscle index out of range");
  if (pinned.size() && (pinned.minCoeff() < 0 || pinned.maxCoeff() >= n))
    fail("pinned vertex index out of range");
  for (Eigen::Index i = 1; i < pinned.size(); ++i)
    if (pinned(i) <= pinned(i - 1)) fail("pinned vertex ids must be sorted and unique");
  if (pinned.size() == 0)
    fail("the scene is not anchored: pin some vertices (scene.pin) or fix a bone; "
         "otherwise it can move freely and no equilibrium is unique");
}

Discretization::Discretization(const Model& model) : geometry(tet_geometry(model.rest, model.tets)) {
  const Eigen::Index n = model.rest.rows();
  free_index = Eigen::VectorXi::Zero(n);
  for (Eigen::Index i = 0; i < model.pinned.size(); ++i) free_index(model.pinned(i)) = -1;
  num_free = 0;
  for (Eigen::Index v = 0; v < n; ++v)
    if (free_index(v) >= 0) free_index(v) = num_free++;
  lumped_mass = Eigen::VectorXd::Zero(n);
  for (Eigen::Index t = 0; t < model.tets.rows(); ++t)
    for (int a = 0; a < 4; ++a)
      lumped_mass(model.tets(t, a)) += 0.25 * model.density(t) * geometry.volume(t);
}

void validate_load(const Model& model, const LoadCase& load) {
  if (load.activation.size() != model.num_muscles) {
    std::ostringstream s;
    s << "activation has " << load.activation.size() << " entries, the model has "
      << model.num_muscles << " muscles";
    fail(s.str());
  }
  check_finite(load.activation, "activation");
  if ((load.activation.array() < 0).any()) fail("activations must be >= 0");
  if (load.pin_positions.rows() != 0 && load.pin_positions.rows() != model.pinned.size()) {
    std::ostringstream s;
    s << "pin_positions has " << load.pin_positions.rows() << " rows, expected "
      << model.pinned.size();
    fail(s.str());
  }
  check_finite(load.pin_positions, "pin positions");
  check_finite(load.gravity, "gravity");
}

Eigen::MatrixX3d pinned_positions(const Model& model, const LoadCase& load) {
  Eigen::MatrixX3d x = model.rest;
  if (load.pin_positions.rows())
    for (Eigen::Index i = 0; i < model.pinned.size(); ++i) x.row(model.pinned(i)) = load.pin_positions.row(i);
  return x;
}

Eigen::VectorXd tet_activation(const Model& model, const LoadCase& load) {
  Eigen::VectorXd a = Eigen::VectorXd::Zero(model.tets.rows());
  for (Eigen::Index t = 0; t < a.size(); ++t)
    if (model.muscle(t) >= 0) a(t) = load.activation(model.muscle(t));
  return a;
}

}  // namespace emu
