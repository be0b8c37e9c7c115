#pragma once
// The elastic term both solvers sum over the tets, evaluated per tet:
//
//   E_el = sum_t V_t Psi_t(F_t),  Psi_t = Stable Neo-Hookean + active fibre
//
// with tet t's material (tet_material: Lame parameters, fibre, activation
// under the load). Bone tets are rigid and carry no elastic energy
// (active(t) is false). Each solver calls it from its own fused per-tet loop:
// EMU on its unknowns F_t with the ACAP coupling added, FEM on F_t(x) chained
// to the tet's corners. Stress and Hessians are per unit rest volume: each
// solver scales by V_t where its chain rule puts it.
#include <Eigen/Core>

#include "emu/energy/material.h"
#include "emu/model/model.h"
#include "emu/model/unknown_layout.h"

namespace emu {

class ElasticTerm {
 public:
  /// act  #T activation of each tet under the load (tet_activation); held by reference
  ElasticTerm(const Model& model, const UnknownLayout& layout, const Eigen::VectorXd& act)
      : model_(model), layout_(layout), act_(act) {}

  /// Whether tet t carries the term (false: a rigid bone tet).
  bool active(Eigen::Index t) const { return !layout_.is_bone_tet(t); }
  /// V_t Psi_t(F); 0 on a bone tet.
  double energy(Eigen::Index t, const Mat3& F) const {
    return active(t) ? layout_.geometry.volume(t) * material_energy(material(t), F) : 0.0;
  }
  /// P_t(F) = dPsi_t/dF (per unit volume); tet t active.
  Mat3 stress(Eigen::Index t, const Mat3& F) const { return material_stress(material(t), F); }
  /// d2Psi_t/dF2 (per unit volume): PSD-filtered into *psd, unfiltered into
  /// *exact (either may be nullptr; from one evaluation); tet t active.
  void hessians(Eigen::Index t, const Mat3& F, EigenFilter filter, Mat9* psd, Mat9* exact) const {
    material_hessians(material(t), F, filter, psd, exact);
  }

 private:
  TetMaterial material(Eigen::Index t) const { return tet_material(model_, act_, t); }

  const Model& model_;
  const UnknownLayout& layout_;
  const Eigen::VectorXd& act_;
};

}  // namespace emu
