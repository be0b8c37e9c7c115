#include "emu/solvers/emu/fit_jacobian.h"

namespace emu {

void FitJacobian::apply(const Mat9X& v, Eigen::MatrixX3d& dx, Mat9X& Fd) const {
  dx.setZero(model_.rest.rows(), 3);
  acap_.fit_of_unknowns(v, dx);
  deformation_gradients(layout_, model_.tets, dx, Fd);
}

void FitJacobian::force_fit(const Eigen::MatrixX3d& f, Mat9X& out) const {
  Eigen::MatrixX3d R;
  acap_.reduce_vertex(f, R);
  Eigen::MatrixXd Z;
  acap_.solve(Eigen::MatrixXd(R), Z);
  Eigen::MatrixX3d y = Eigen::MatrixX3d::Zero(model_.rest.rows(), 3);
  acap_.expand(Eigen::MatrixX3d(Z), y);
  deformation_gradients(layout_, model_.tets, y, out);
}

void FitJacobian::transpose_apply(const Eigen::MatrixX3d& f, Mat9X& out) const {
  Mat9X per_tet;
  force_fit(f, per_tet);
  const auto& wv = acap_.weight_volume();
  for (Eigen::Index t = 0; t < per_tet.cols(); ++t) per_tet.col(t) *= wv(t);
  reduce_to_unknowns(layout_, per_tet, out);
}

void FitJacobian::add_hessian_product(const Eigen::SparseMatrix<double>& H, const Mat9X& v, Mat9X& out) const {
  if (H.nonZeros() == 0) return;
  Eigen::MatrixX3d dx;
  Mat9X Fd;
  apply(v, dx, Fd);
  // H acts on vertex-major dofs 3 w + i: the rows of dx, flattened row by row.
  using RowMajorX3 = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
  const RowMajorX3 dxr = dx;
  const Eigen::VectorXd Hdx = H * Eigen::Map<const Eigen::VectorXd>(dxr.data(), dxr.size());
  const Eigen::MatrixX3d f = Eigen::Map<const RowMajorX3>(Hdx.data(), dx.rows(), 3);
  Mat9X add;
  transpose_apply(f, add);
  out += add;
}

}  // namespace emu
