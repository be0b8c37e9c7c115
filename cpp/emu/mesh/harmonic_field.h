#pragma once
// A harmonic scalar field on a tet mesh: the P1 Laplace equation
//   sum_b L_ab phi_b = 0 at every free vertex a,  L_ab = sum_t V_t b_a . b_b,
// with phi prescribed on the fixed vertices. Used for muscle fibre fields
// (+1 on one attachment, -1 on the other; fibres along grad phi).
#include <Eigen/Core>

namespace emu {

/// X       #V by 3 rest positions
/// T       #T by 4 tets (positively oriented) of the region to solve on
/// fixed   #F vertex ids with prescribed values (vertices of no tet are ignored)
/// values  #F prescribed values
/// Returns #V values (fixed ones as given, vertices of no tet 0). Throws
/// std::invalid_argument if a connected piece of the region has no fixed vertex.
Eigen::VectorXd harmonic_field(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T, const Eigen::VectorXi& fixed,
                               const Eigen::VectorXd& values);

/// Per-tet gradient of a P1 field phi (#V): #T by 3.
Eigen::MatrixX3d tet_gradients(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T, const Eigen::VectorXd& phi);

}  // namespace emu
