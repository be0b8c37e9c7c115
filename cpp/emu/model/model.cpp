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

void need_per_tet(const Model& md, Eigen::Index rows, const char* what) {
  if (rows != md.tets.rows()) {
    std::ostringstream s;
    s << what << " has " << rows << " entries, expected one per tet (" << md.tets.rows() << ")";
    fail(s.str());
  }
}
}  // namespace

namespace {
// #V rest positions, tet indices in range, one material entry per tet.
void check_mesh_and_materials(const Model& md) {
  const Eigen::Index n = md.rest.rows(), m = md.tets.rows();
  if (n == 0 || m == 0) fail("the model has no vertices or no tets");
  check_finite(md.rest, "rest positions");
  if (md.tets.minCoeff() < 0 || md.tets.maxCoeff() >= n) {
    std::ostringstream s;
    s << "tet indices must lie in [0, " << n << "); got range [" << md.tets.minCoeff() << ", "
      << md.tets.maxCoeff() << "]";
    fail(s.str());
  }
  need_per_tet(md, md.mu.size(), "mu");
  need_per_tet(md, md.lambda.size(), "lambda");
  need_per_tet(md, md.density.size(), "density");
  need_per_tet(md, md.acap_weight.size(), "acap_weight");
  need_per_tet(md, md.fiber.rows(), "fiber");
  need_per_tet(md, md.muscle.size(), "muscle");
  check_finite(md.mu, "mu");
  check_finite(md.lambda, "lambda");
  check_finite(md.fiber, "fiber");
  check_finite(md.density, "density");
  check_finite(md.acap_weight, "acap_weight");
  if ((md.mu.array() <= 0).any() || (md.lambda.array() <= 0).any())
    fail("Lame parameters must be positive (Poisson ratio in (0, 0.5))");
  if ((md.acap_weight.array() <= 0).any()) fail("ACAP weights must be positive");
  if (md.muscle.size() && (md.muscle.maxCoeff() >= md.num_muscles || md.muscle.minCoeff() < -1))
    fail("muscle index out of range");
  if (md.pinned.size() && (md.pinned.minCoeff() < 0 || md.pinned.maxCoeff() >= n))
    fail("pinned vertex index out of range");
  for (Eigen::Index i = 1; i < md.pinned.size(); ++i)
    if (md.pinned(i) <= md.pinned(i - 1)) fail("pinned vertex ids must be sorted and unique");
}

// Movable bones: per-tet ids, each bone with tets and no muscle tet among them; springs.
void check_bones(const Model& md) {
  const Eigen::Index m = md.tets.rows();
  if (md.bone.size() != 0 && md.bone.size() != m) need_per_tet(md, md.bone.size(), "bone");
  if (md.bone.size()) {
    if (md.bone.minCoeff() < -1 || md.bone.maxCoeff() >= md.num_bones) fail("bone index out of range");
    std::vector<int> count(md.num_bones, 0);
    for (Eigen::Index t = 0; t < m; ++t)
      if (md.bone(t) >= 0) {
        ++count[md.bone(t)];
        if (md.muscle(t) >= 0) fail("a tet cannot belong to both a muscle and a bone");
      }
    for (int b = 0; b < md.num_bones; ++b)
      if (count[b] == 0) fail("movable bone " + std::to_string(b) + " has no tets");
  } else if (md.num_bones != 0) {
    fail("num_bones > 0 but no per-tet bone ids were given");
  }
  if (md.bone_stiffness.size() != 0 && md.bone_stiffness.size() != md.num_bones)
    fail("bone_stiffness needs one value per movable bone (" + std::to_string(md.num_bones) + "), got " +
         std::to_string(md.bone_stiffness.size()));
  check_finite(md.bone_stiffness, "bone_stiffness");
  if (md.bone_stiffness.size() && md.bone_stiffness.minCoeff() < 0) fail("bone_stiffness must be >= 0");
  if (md.joint_points.rows() != md.joint_bones.rows()) fail("joint_points and joint_bones differ in rows");
  check_finite(md.joint_points, "joint points");
  for (Eigen::Index i = 0; i < md.joint_bones.rows(); ++i) {
    const int a = md.joint_bones(i, 0), b = md.joint_bones(i, 1);
    if (a < 0 || a >= md.num_bones || b < -1 || b >= md.num_bones || a == b)
      fail("declared joint " + std::to_string(i) + " names bones (" + std::to_string(a) + ", " + std::to_string(b) +
           "): the first must be a movable bone, the second another movable bone or -1 (the world)");
  }
}

// The scene's tets: num_scene_tets and the distinct scene tet of each tet.
void check_scene_tets(const Model& md) {
  const Eigen::Index m = md.tets.rows();
  if (md.num_scene_tets < 0 || (md.num_scene_tets > 0 && md.num_scene_tets < m))
    fail("num_scene_tets must be 0 (the scene's tets are these) or at least #T (" + std::to_string(m) + ")");
  if (md.scene_tet.size()) {
    need_per_tet(md, md.scene_tet.size(), "scene_tet");
    const Eigen::Index count = md.scene_tet_count();
    std::vector<char> seen(count, 0);
    for (Eigen::Index t = 0; t < m; ++t) {
      const int s = md.scene_tet(t);
      if (s < 0 || s >= count || seen[s])
        fail("scene_tet must name distinct scene tets in [0, " + std::to_string(count) + "); tet " +
             std::to_string(t) + " names " + std::to_string(s));
      seen[s] = 1;
    }
  } else if (md.num_scene_tets > m) {
    fail("num_scene_tets exceeds #T: give scene_tet, the scene's tet of each tet");
  }
}
}  // namespace

void Model::validate() const {
  check_mesh_and_materials(*this);
  check_bones(*this);
  check_scene_tets(*this);
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
  if (!std::isfinite(load.inertia_weight) || load.inertia_weight < 0)
    fail("inertia_weight must be finite and >= 0 (1 / h_eff^2 of a time step; 0: quasi-static)");
  if (load.inertia_weight > 0 && load.inertia_target.rows() != model.rest.rows()) {
    std::ostringstream s;
    s << "inertia_target has " << load.inertia_target.rows() << " rows, expected one per vertex, "
      << model.rest.rows();
    fail(s.str());
  }
  check_finite(load.inertia_target, "inertia target");
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
