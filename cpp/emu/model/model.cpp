#include "emu/model/model.h"

#include <algorithm>
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
  if (bone.size() != 0 && bone.size() != m) need(bone.size(), "bone");
  if (bone.size()) {
    if (bone.minCoeff() < -1 || bone.maxCoeff() >= num_bones) fail("bone index out of range");
    std::vector<int> count(num_bones, 0);
    for (Eigen::Index t = 0; t < m; ++t)
      if (bone(t) >= 0) {
        ++count[bone(t)];
        if (muscle(t) >= 0) fail("a tet cannot belong to both a muscle and a bone");
      }
    for (int b = 0; b < num_bones; ++b)
      if (count[b] == 0) fail("movable bone " + std::to_string(b) + " has no tets");
  } else if (num_bones != 0) {
    fail("num_bones > 0 but no per-tet bone ids were given");
  }
  if (bone_stiffness.size() != 0 && bone_stiffness.size() != num_bones)
    fail("bone_stiffness needs one value per movable bone (" + std::to_string(num_bones) + "), got " +
         std::to_string(bone_stiffness.size()));
  check_finite(bone_stiffness, "bone_stiffness");
  if (bone_stiffness.size() && bone_stiffness.minCoeff() < 0) fail("bone_stiffness must be >= 0");
  if (joint_points.rows() != joint_bones.rows()) fail("joint_points and joint_bones differ in rows");
  check_finite(joint_points, "joint points");
  for (Eigen::Index i = 0; i < joint_bones.rows(); ++i) {
    const int a = joint_bones(i, 0), b = joint_bones(i, 1);
    if (a < 0 || a >= num_bones || b < -1 || b >= num_bones || a == b)
      fail("declared joint " + std::to_string(i) + " names bones (" + std::to_string(a) + ", " + std::to_string(b) +
           "): the first must be a movable bone, the second another movable bone or -1 (the world)");
  }
  if (num_scene_tets < 0 || (num_scene_tets > 0 && num_scene_tets < m))
    fail("num_scene_tets must be 0 (the scene's tets are these) or at least #T (" + std::to_string(m) + ")");
  if (scene_tet.size()) {
    need(scene_tet.size(), "scene_tet");
    const Eigen::Index count = scene_tet_count();
    std::vector<char> seen(count, 0);
    for (Eigen::Index t = 0; t < m; ++t) {
      const int s = scene_tet(t);
      if (s < 0 || s >= count || seen[s])
        fail("scene_tet must name distinct scene tets in [0, " + std::to_string(count) + "); tet " +
             std::to_string(t) + " names " + std::to_string(s));
      seen[s] = 1;
    }
  } else if (num_scene_tets > m) {
    fail("num_scene_tets exceeds #T: give scene_tet, the scene's tet of each tet");
  }
  if (pinned.size() == 0)
    fail("the scene is not anchored: pin some vertices (scene.pin) or fix a bone; "
         "otherwise it can move freely and no equilibrium is unique");
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
  if (load.joint_targets.rows() != 0 && load.joint_targets.rows() != model.joint_points.rows()) {
    std::ostringstream s;
    s << "joint_targets has " << load.joint_targets.rows() << " rows, expected " << model.joint_points.rows();
    fail(s.str());
  }
  check_finite(load.joint_targets, "joint targets");
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
