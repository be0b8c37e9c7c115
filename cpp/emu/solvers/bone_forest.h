#pragma once
// The forest of movable bones and their joints, shared by FEM's rigid bones
// (rigid_bones.h) and EMU's joint coordinates (joint_coordinates.h).
//
// A root is held by the world (joint points shared with pinned vertices,
// fixed bones or declared world joints: one point a ball, two or more on a
// line a hinge) or by nothing (free); every other bone hangs from the bone
// that reached it first in a breadth-first walk from the roots, on its joint
// points with that parent (one point: a ball; two or more on a line: a hinge,
// its axis carried by the parent). Points off a line weld the two; a closed
// loop of joints has no tree: both are errors of the constructor.
#include <vector>

#include <Eigen/Core>

#include "emu/energy/types.h"
#include "emu/model/unknown_layout.h"

namespace emu {

struct BoneForest {
  enum class Kind { Free, Ball, Hinge };
  struct Node {
    Kind kind = Kind::Free;
    int parent = -1;                 // the bone it hangs from (-1: a root)
    int axis_end = -1;               // hinge: the anchor that spans the axis with the pivot
    Vec3 P = Vec3::Zero();           // rest pivot (free: the bone's centroid)
    Vec3 rest_axis = Vec3::UnitX();  // hinge: the unit axis at rest
    std::vector<int> anchors;        // the layout's joint points with its parent (or the world)
    std::vector<int> chain;          // its ancestors and itself, root first
    std::vector<int> below;          // itself and its descendants
  };

  /// Throws std::invalid_argument naming the bones for a weld (joint points
  /// not on one line) or a closed loop of joints. diag: the scene's bounding-box
  /// diagonal (the scale of "on one line").
  BoneForest(const UnknownLayout& layout, double diag);
  /// A forest given node by node: `bones` with kind, parent, rest axis (and
  /// anchors for a root hinge), roots before their children in `order`; chain
  /// and below are filled in.
  BoneForest(std::vector<Node> nodes, std::vector<int> roots_first);

  std::vector<Node> bones;  // per movable bone
  std::vector<int> order;   // roots first, then each bone after its parent

 private:
  void build(const UnknownLayout& layout);
  void link();  // chain and below from parent and order
  void set_kind(const UnknownLayout& layout, int b, double diag);
};

}  // namespace emu
