#pragma once
// EMU's movable bones on SO(3). Each movable bone's unknown F_b is a rotation
// R, kept one: steps for it lie in the tangent space {R [w]x}, the line search
// retracts R + s d to the nearest rotation (polar decomposition), and the
// Newton Hessian is the Riemannian one,
//   Hess[v] = P_T(H v - v sym(R^T g)),   P_T(M) = R skew(R^T M).
// The unknowns are 9 x #unknowns (vec(F) column-major per column): the soft
// tets' first, then one per movable bone from column num_soft; the functions
// here touch only the bone columns.
#include <Eigen/Core>

#include "emu/energy/types.h"
#include "emu/solvers/emu/acap.h"

namespace emu::bone_rotations {

/// v's bone columns projected to the tangent space at F's rotations.
void project_tangent(const Mat9X& F, int num_soft, Mat9X& v);

/// out = F + s d, its bone columns retracted to the nearest rotation.
void retract(const Mat9X& F, const Mat9X& d, double s, int num_soft, Mat9X& out);

/// One bone's Riemannian Hessian product from the Euclidean one HV = H v at
/// rotation R with Euclidean gradient G and direction V (all 3x3). With
/// `curvature` the term -V sym(R^T G) is added (the exact Hessian); without
/// it (the PSD-filtered Hessian) only a joint spring's curvature is kept,
/// clamped PSD: its Euclidean Hessian is zero, so this term is all of it
/// (spring_stiffness k in N m / rad; 0: no spring).
Mat3 riemannian_block(const Mat3& R, const Mat3& G, const Mat3& V, const Mat3& HV, bool curvature,
                      double spring_stiffness);

/// out's bone columns (holding H v) made Riemannian by riemannian_block;
/// spring_stiffness  #bones, k per movable bone (shorter: no spring beyond).
void riemannian_columns(const Mat9X& F, const Mat9X& g, const Mat9X& v, bool curvature, int num_soft,
                        const Eigen::VectorXd& spring_stiffness, Mat9X& out);

}  // namespace emu::bone_rotations
