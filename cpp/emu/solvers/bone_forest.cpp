#include "emu/solvers/bone_forest.h"

#include <algorithm>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>

namespace emu {

BoneForest::BoneForest(const UnknownLayout& layout, double diag) : bones(layout.num_bones) {
  build(layout);
  for (int b = 0; b < layout.num_bones; ++b) set_kind(layout, b, diag);
}

void BoneForest::build(const UnknownLayout& layout) {
  const int nb = static_cast<int>(bones.size());
  // Joint points per bone with the world, and per pair of movable bones.
  std::vector<std::vector<int>> world(nb);
  std::map<std::pair<int, int>, std::vector<int>> links;
  for (size_t i = 0; i < layout.joints.size(); ++i) {
    const JointPoint& j = layout.joints[i];
    if (j.other < 0) world[j.bone].push_back(static_cast<int>(i));
    else links[{std::min(j.bone, j.other), std::max(j.bone, j.other)}].push_back(static_cast<int>(i));
  }
  std::vector<std::vector<int>> neighbours(nb);
  for (const auto& link : links) {
    neighbours[link.first.first].push_back(link.first.second);
    neighbours[link.first.second].push_back(link.first.first);
  }
  // Roots: the bones the world holds, then (a piece nothing holds) its lowest
  // bone, free; every other bone hangs from the bone that reached it first.
  std::vector<char> seen(nb, 0);
  for (int b = 0; b < nb; ++b)
    if (!world[b].empty()) {
      seen[b] = 1;
      bones[b].anchors = world[b];
    }
  auto grow = [&](int root) {
    size_t head = order.size();
    order.push_back(root);
    while (head < order.size()) {
      const int u = order[head++];
      for (int w : neighbours[u]) {
        if (w == bones[u].parent) continue;
        if (seen[w])
          throw std::invalid_argument("movable bones " + std::to_string(u) + " and " + std::to_string(w) +
                                      " close a loop of joints (through each other, pinned vertices or fixed "
                                      "bones); the FEM solver needs the bones' joints to form a tree: fix a bone "
                                      "of the loop or remove a joint");
        seen[w] = 1;
        bones[w].parent = u;
        bones[w].anchors = links[{std::min(u, w), std::max(u, w)}];
        order.push_back(w);
      }
    }
  };
  for (int b = 0; b < nb; ++b)
    if (!world[b].empty()) grow(b);
  for (int b = 0; b < nb; ++b)
    if (!seen[b]) {
      seen[b] = 1;
      grow(b);
    }
  link();
}

BoneForest::BoneForest(std::vector<Node> nodes, std::vector<int> roots_first)
    : bones(std::move(nodes)), order(std::move(roots_first)) {
  link();
}

void BoneForest::link() {
  for (int b : order) {
    Node& B = bones[b];
    B.chain.clear();
    B.below.clear();
  }
  for (int b : order) {
    Node& B = bones[b];
    if (B.parent >= 0) B.chain = bones[B.parent].chain;
    B.chain.push_back(b);
    for (int a : B.chain) bones[a].below.push_back(b);
  }
}

void BoneForest::set_kind(const UnknownLayout& layout, int b, double diag) {
  Node& B = bones[b];
  if (B.anchors.empty()) {
    B.kind = Kind::Free;
    B.P = layout.bone_center.row(b).transpose();
    return;
  }
  const Vec3 X0 = layout.joints[B.anchors[0]].rest;
  for (size_t i = 1; i < B.anchors.size(); ++i)
    if (B.axis_end < 0 && (layout.joints[B.anchors[i]].rest - X0).norm() > 1e-9 * diag)
      B.axis_end = static_cast<int>(i);
  B.kind = B.axis_end < 0 ? Kind::Ball : Kind::Hinge;
  B.P = X0;
  if (B.axis_end < 0) return;
  const Vec3 a = (layout.joints[B.anchors[B.axis_end]].rest - X0).normalized();
  B.rest_axis = a;
  for (int i : B.anchors) {
    const Vec3 r = layout.joints[i].rest - X0;
    if ((r - r.dot(a) * a).norm() <= 1e-6 * diag) continue;
    if (B.parent >= 0)
      throw std::invalid_argument("movable bones " + std::to_string(B.parent) + " and " + std::to_string(b) +
                                  " are welded: the points they share are not on one line; make them one bone");
    throw std::invalid_argument("movable bone " + std::to_string(b) +
                                " is welded: its joints with pinned vertices or fixed bones are not on "
                                "one line; fix the bone instead");
  }
}

}  // namespace emu
