#include "emu/model/unknown_layout.h"

#include <algorithm>

namespace emu {

UnknownLayout::UnknownLayout(const Model& model) : geometry(tet_geometry(model.rest, model.tets)) {
  const Eigen::Index n = model.rest.rows(), m = model.tets.rows();
  num_bones = model.bone.size() ? model.num_bones : 0;
  std::vector<char> pinned(n, 0);
  for (Eigen::Index i = 0; i < model.pinned.size(); ++i) pinned[model.pinned(i)] = 1;
  // Bones of each vertex (sorted, unique).
  std::vector<std::vector<int>> bones_of(n);
  for (Eigen::Index t = 0; t < m && num_bones; ++t) {
    const int b = model.bone(t);
    if (b < 0) continue;
    for (int a = 0; a < 4; ++a) {
      auto& l = bones_of[model.tets(t, a)];
      if (std::find(l.begin(), l.end(), b) == l.end()) l.insert(std::upper_bound(l.begin(), l.end(), b), b);
    }
  }
  vertex_bone = Eigen::VectorXi::Constant(n, -1);
  bone_center = Eigen::MatrixX3d::Zero(num_bones, 3);
  Eigen::VectorXd bone_count = Eigen::VectorXd::Zero(num_bones);
  for (Eigen::Index v = 0; v < n; ++v) {
    const auto& l = bones_of[v];
    for (int b : l) {
      bone_center.row(b) += model.rest.row(v);
      bone_count(b) += 1;
    }
    if (l.empty()) continue;
    const Eigen::Vector3d X = model.rest.row(v).transpose();
    if (pinned[v]) {
      for (int b : l) joints.push_back({X, static_cast<int>(v), b, -1, -1});
    } else {
      vertex_bone(v) = l[0];
      for (size_t i = 1; i < l.size(); ++i) joints.push_back({X, static_cast<int>(v), l[i], l[0], -1});
    }
  }
  for (Eigen::Index i = 0; i < model.joint_points.rows(); ++i)
    joints.push_back({model.joint_points.row(i).transpose(), -1, model.joint_bones(i, 0), model.joint_bones(i, 1),
                      static_cast<int>(i)});
  for (int b = 0; b < num_bones; ++b) bone_center.row(b) /= bone_count(b);
  free_index = Eigen::VectorXi::Zero(n);
  num_free = 0;
  for (Eigen::Index v = 0; v < n; ++v) free_index(v) = (pinned[v] || vertex_bone(v) >= 0) ? -1 : num_free++;
  num_soft = 0;
  tet_unknown.resize(m);
  for (Eigen::Index t = 0; t < m; ++t)
    if (!num_bones || model.bone(t) < 0) tet_unknown(t) = num_soft++;
  for (Eigen::Index t = 0; t < m; ++t)
    if (num_bones && model.bone(t) >= 0) tet_unknown(t) = num_soft + model.bone(t);
  num_unknowns = num_soft + num_bones;
  unknown_ptr.assign(num_unknowns + 1, 0);
  for (Eigen::Index t = 0; t < m; ++t) ++unknown_ptr[tet_unknown(t) + 1];
  for (int u = 0; u < num_unknowns; ++u) unknown_ptr[u + 1] += unknown_ptr[u];
  unknown_tets.resize(m);
  std::vector<int> fill(unknown_ptr.begin(), unknown_ptr.end() - 1);
  for (Eigen::Index t = 0; t < m; ++t) unknown_tets[fill[tet_unknown(t)]++] = static_cast<int>(t);
  lumped_mass = Eigen::VectorXd::Zero(n);
  for (Eigen::Index t = 0; t < model.tets.rows(); ++t)
    for (int a = 0; a < 4; ++a)
      lumped_mass(model.tets(t, a)) += 0.25 * model.density(t) * geometry.volume(t);
}

}  // namespace emu
