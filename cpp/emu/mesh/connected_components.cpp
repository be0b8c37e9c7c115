#include "emu/mesh/connected_components.h"

#include <stdexcept>
#include <string>
#include <vector>

namespace emu {

Eigen::VectorXi connected_components(int num_vertices, const Eigen::MatrixX4i& T) {
  if (num_vertices < 0) throw std::invalid_argument("connected_components: negative vertex count");
  std::vector<int> parent(num_vertices);
  for (int v = 0; v < num_vertices; ++v) parent[v] = v;
  // find with path halving; union hangs the larger root under the smaller, so
  // a root is always the smallest id of its piece
  auto find = [&](int v) {
    while (parent[v] != v) {
      parent[v] = parent[parent[v]];
      v = parent[v];
    }
    return v;
  };
  for (Eigen::Index t = 0; t < T.rows(); ++t) {
    for (int a = 0; a < 4; ++a)
      if (T(t, a) < 0 || T(t, a) >= num_vertices)
        throw std::invalid_argument("connected_components: tet " + std::to_string(t) + " has vertex id " +
                                    std::to_string(T(t, a)) + " outside [0, " + std::to_string(num_vertices) + ")");
    int root = find(T(t, 0));
    for (int a = 1; a < 4; ++a) {
      const int other = find(T(t, a));
      if (other < root) parent[root] = other, root = other;
      else if (other > root) parent[other] = root;
    }
  }
  Eigen::VectorXi label(num_vertices);
  for (int v = 0; v < num_vertices; ++v) label(v) = find(v);
  return label;
}

}  // namespace emu
