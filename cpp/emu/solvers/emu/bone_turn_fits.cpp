#include "emu/solvers/emu/bone_turn_fits.h"

namespace emu {

BoneTurnFits::BoneTurnFits(const UnknownLayout& layout, const FitJacobian& jacobian) : layout_(layout) {
  fits_.resize(layout_.num_bones);
  Eigen::MatrixX3d dx;
  Mat9X Fd;
  for (int b = 0; b < layout_.num_bones; ++b) {
    UnitTurn& f = fits_[b];
    Mat9X Z = Mat9X::Zero(9, layout_.num_unknowns);
    Z.col(layout_.num_soft + b) = flatten(Mat3::Identity());
    jacobian.apply(Z, dx, Fd);
    f.follow.resize(9, layout_.num_soft);
    for (int u = 0; u < layout_.num_soft; ++u) f.follow.col(u) = Fd.col(layout_.unknown_tets[u]);
    Z.leftCols(layout_.num_soft) = f.follow;
    jacobian.apply(Z, dx, f.fit);
  }
}

std::vector<const Mat9X*> BoneTurnFits::follow_fields() const {
  std::vector<const Mat9X*> f;
  for (const UnitTurn& t : fits_) f.push_back(&t.follow);
  return f;
}

double BoneTurnFits::bytes() const {
  double n = 0;
  for (const UnitTurn& t : fits_) n += double(t.follow.size() + t.fit.size());
  return 8.0 * n;
}

template <int N>
void BoneTurnFits::turns(const std::vector<Mat9>& A, int b, const std::array<Mat3, N>& M, double alpha,
                         const Eigen::VectorXd& wv, std::array<Mat9X, N>& Z, std::array<Mat9X, N>& HZ) const {
  // On a soft unknown u (tet t): Z_k = vec(M_k Phi_u), H Z_k = A_u Z_k -
  // alpha w V vec(M_k fit_t) (the Hessian product with Z_k's fit, M_k times the unit one).
  const UnitTurn& f = fits_[b];
  const int ns = layout_.num_soft, nu = layout_.num_unknowns;
  for (int k = 0; k < N; ++k) {
    Z[k].resize(9, nu);
    HZ[k].resize(9, nu);
  }
#pragma omp parallel for schedule(static)
  for (int u = 0; u < ns; ++u) {
    const int t = layout_.unknown_tets[layout_.unknown_ptr[u]];
    const Eigen::Map<const Mat3> follow(f.follow.col(u).data()), fit(f.fit.col(t).data());
    for (int k = 0; k < N; ++k) {
      const Vec9 z = flatten(Mat3(M[k] * follow));
      Z[k].col(u) = z;
      HZ[k].col(u) = A[u].lazyProduct(z) - (alpha * wv(t)) * flatten(Mat3(M[k] * fit));
    }
  }
  for (int u = ns; u < nu; ++u) {  // bones: their own turn (b) or none; the fit's pull over their tets
    for (int k = 0; k < N; ++k) {
      Z[k].col(u) = u == ns + b ? flatten(M[k]) : Vec9::Zero();
      Vec9 pull = Vec9::Zero();
      for (int i = layout_.unknown_ptr[u]; i < layout_.unknown_ptr[u + 1]; ++i) {
        const int t = layout_.unknown_tets[i];
        pull += (alpha * wv(t)) * flatten(Mat3(M[k] * unflatten(f.fit.col(t))));
      }
      HZ[k].col(u) = A[u].lazyProduct(Z[k].col(u)) - pull;
    }
  }
}

// The coarse space's rebuild (N = 3) and EmuSolverTesting's single turn (N = 1).
template void BoneTurnFits::turns<1>(const std::vector<Mat9>&, int, const std::array<Mat3, 1>&, double,
                                     const Eigen::VectorXd&, std::array<Mat9X, 1>&, std::array<Mat9X, 1>&) const;
template void BoneTurnFits::turns<3>(const std::vector<Mat9>&, int, const std::array<Mat3, 3>&, double,
                                     const Eigen::VectorXd&, std::array<Mat9X, 3>&, std::array<Mat9X, 3>&) const;

}  // namespace emu
