#pragma once
// The form Newton-Krylov's three preconditioners share (woodbury.h,
// schur_preconditioner.h, constant_schur.h): with the per-unknown block
// inverses A^-1 and a position-space middle operator P,
//   out = A^-1 r + s A^-1 C^T P (C A^-1 r),
// where P is X^-1 through the k modes (Woodbury, s = 1), S^-1 (Schur,
// s = alpha) or the factor of K for S0 = c K (constant Schur, s = alpha / c).
// Two block passes, one
// right-hand side C A^-1 r (#dofs by 3) for P, one C^T of P's answer.
#include <vector>

#include <Eigen/Core>

#include "emu/energy/types.h"
#include "emu/linalg/rounded_block.h"
#include "emu/model/unknown_layout.h"
#include "emu/solvers/emu/acap.h"

namespace emu {

/// Work arrays of apply_schur_form, kept by the caller between calls (a CG
/// iteration makes one call; per-tet arrays are megabytes on large meshes).
/// A preconditioner holding one is not reentrant: its apply() runs serially
/// (from PCG, L-BFGS and the bone coarse space, never inside a parallel region).
struct SchurFormWork {
  Mat9X per_tet, per_unknown;  // 9 x #T, 9 x #unknowns (bones only)
  Eigen::MatrixX3d y, u;       // C A^-1 r and P of it: #dofs by 3
};

/// out = A^-1 r + s A^-1 C^T middle(C A^-1 r). r, out: 9 x #unknowns; Ainv:
/// #unknowns blocks (Mat9, or Mat9f rounded by round_spd_block); middle(y, u):
/// u = P y (y, u #dofs by 3). With blocks_only, out = A^-1 r (the middle term
/// left out).
template <class Block, class Middle>
void apply_schur_form(const UnknownLayout& layout, const AcapOperator& acap, const std::vector<Block>& Ainv, double s,
                      const Mat9X& r, Mat9X& out, SchurFormWork& w, Middle&& middle, bool blocks_only = false) {
  const long n = r.cols();
  out.resize(9, n);
#pragma omp parallel for schedule(static)
  for (long u = 0; u < n; ++u) out.col(u) = block_times(Ainv[u], r.col(u));
  if (blocks_only) return;
  acap.apply_C_of_unknowns(out, w.y);
  middle(w.y, w.u);
  acap.apply_CT(w.u, w.per_tet);
  const Mat9X* ct = &w.per_tet;
  if (layout.num_bones) {  // sums over a bone's tets (without bones per_tet is per unknown)
    reduce_to_unknowns(layout, w.per_tet, w.per_unknown);
    ct = &w.per_unknown;
  }
#pragma omp parallel for schedule(static)
  for (long u = 0; u < n; ++u) out.col(u) += s * block_times(Ainv[u], ct->col(u));
}

}  // namespace emu
