#include "emu/mesh/tet_geometry.h"

#include <sstream>
#include <stdexcept>

namespace emu {

Eigen::VectorXd signed_volumes(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T) {
  Eigen::VectorXd v(T.rows());
  for (Eigen::Index t = 0; t < T.rows(); ++t) {
    Mat3 Dm;
    for (int a = 0; a < 3; ++a) Dm.col(a) = (X.row(T(t, a + 1)) - X.row(T(t, 0))).transpose();
    v(t) = Dm.determinant() / 6.0;
  }
  return v;
}

TetGeometry tet_geometry(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T) {
  TetGeometry g;
  const Eigen::Index m = T.rows();
  g.volume.resize(m);
  g.grad.resize(m);
  for (Eigen::Index t = 0; t < m; ++t) {
    Mat3 Dm;
    for (int a = 0; a < 3; ++a) Dm.col(a) = (X.row(T(t, a + 1)) - X.row(T(t, 0))).transpose();
    const double det = Dm.determinant();
    if (!(det > 0.0)) {
      std::ostringstream msg;
      msg << "tet " << t << " has non-positive rest volume " << det / 6.0
          << "; reorient or remove it before building the model";
      throw std::invalid_argument(msg.str());
    }
    const Mat3 Dinv = Dm.inverse();  // F = Ds Dinv: b_{a+1}[k] = Dinv(a, k)
    ShapeGrads b;
    b.bottomRows<3>() = Dinv;
    b.row(0) = -Dinv.colwise().sum();
    g.grad[t] = b;
    g.volume(t) = det / 6.0;
  }
  return g;
}

}  // namespace emu
