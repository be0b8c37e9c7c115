#pragma once
// The order the solvers store a model's tets in: along a Z-order curve
// through their centroids (mesh/spatial_order.h), so that tets near each other
// in space are near each other in memory. Meshes from mesh generators and
// research code often list their tets in no spatial order, and a solver's
// per-vertex sums then read its per-tet arrays at random.
#include "emu/model/model.h"

namespace emu {

/// The model validated and with its tets (and every per-tet array) in
/// spatial_order; scene_tet is carried along, so that tet t of the result is
/// still the scene's tet scene_index(t). Ties keep the model's order.
Model along_curve(const Model& model);

}  // namespace emu
