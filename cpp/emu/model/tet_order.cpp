#include "emu/model/tet_order.h"

#include <vector>

#include "emu/mesh/spatial_order.h"

namespace emu {
namespace {
template <class Rows>
Rows permute_rows(const Rows& a, const std::vector<int>& order) {
  if (a.rows() == 0) return a;
  Rows out(a.rows(), a.cols());
  for (size_t i = 0; i < order.size(); ++i) out.row(i) = a.row(order[i]);
  return out;
}
}  // namespace

Model along_curve(const Model& model) {
  model.validate();
  const std::vector<int> order = spatial_order(model.rest, model.tets);
  Model out = model;
  out.tets = permute_rows(model.tets, order);
  out.mu = permute_rows(model.mu, order);
  out.lambda = permute_rows(model.lambda, order);
  out.density = permute_rows(model.density, order);
  out.acap_weight = permute_rows(model.acap_weight, order);
  out.fiber = permute_rows(model.fiber, order);
  out.muscle = permute_rows(model.muscle, order);
  out.bone = permute_rows(model.bone, order);
  out.num_scene_tets = static_cast<int>(model.scene_tet_count());
  out.scene_tet.resize(model.tets.rows());
  for (size_t i = 0; i < order.size(); ++i) out.scene_tet(i) = static_cast<int>(model.scene_index(order[i]));
  return out;
}

}  // namespace emu
