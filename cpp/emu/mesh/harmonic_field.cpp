#include "emu/mesh/harmonic_field.h"

#include <stdexcept>
#include <vector>

#include "emu/linalg/cholmod_factor.h"
#include "emu/mesh/block_pattern.h"
#include "emu/mesh/tet_geometry.h"

namespace emu {

Eigen::VectorXd harmonic_field(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T, const Eigen::VectorXi& fixed,
                               const Eigen::VectorXd& values) {
  if (fixed.size() != values.size()) throw std::invalid_argument("fixed and values differ in length");
  const Eigen::Index n = X.rows(), m = T.rows();
  if (fixed.size() && (fixed.minCoeff() < 0 || fixed.maxCoeff() >= n))
    throw std::invalid_argument("fixed vertex id out of range");
  const TetGeometry geo = tet_geometry(X, T);
  Eigen::VectorXd phi = Eigen::VectorXd::Zero(n);
  std::vector<char> is_fixed(n, 0), used(n, 0);
  for (Eigen::Index i = 0; i < fixed.size(); ++i) {
    is_fixed[fixed(i)] = 1;
    phi(fixed(i)) = values(i);
  }
  for (Eigen::Index t = 0; t < m; ++t)
    for (int a = 0; a < 4; ++a) used[T(t, a)] = 1;
  Eigen::VectorXi free_index = Eigen::VectorXi::Constant(n, -1);
  int nf = 0;
  for (Eigen::Index v = 0; v < n; ++v)
    if (used[v] && !is_fixed[v]) free_index(v) = nf++;
  if (nf == 0) return phi;
  BlockPattern pattern(T, free_index, nf, 1);
  std::vector<double> element(m * 16), corner(m * 4);
  for (Eigen::Index t = 0; t < m; ++t) {
    const ShapeGrads& b = geo.grad[t];
    Eigen::Map<Eigen::Matrix4d>(element.data() + t * 16) = geo.volume(t) * b * b.transpose();
    // right-hand side: -sum over fixed corners c of L_ac phi_c
    Vec3 g = Vec3::Zero();
    for (int c = 0; c < 4; ++c)
      if (is_fixed[T(t, c)]) g += phi(T(t, c)) * b.row(c).transpose();
    for (int a = 0; a < 4; ++a) corner[t * 4 + a] = -geo.volume(t) * b.row(a).dot(g);
  }
  std::vector<double> vals(pattern.nnz());
  pattern.assemble(element.data(), vals.data());
  Eigen::VectorXd rhs(nf), sol(nf);
  pattern.gather(corner.data(), 1, rhs.data());
  CholmodFactor f;
  f.analyze(pattern.rows(), pattern.col_ptr().data(), pattern.row_index().data());
  if (!f.factorize(vals.data()))
    throw std::invalid_argument("a connected piece of the region has no fixed vertex; the harmonic field is "
                                "undetermined there");
  f.solve(rhs.data(), sol.data(), 1);
  for (Eigen::Index v = 0; v < n; ++v)
    if (free_index(v) >= 0) phi(v) = sol(free_index(v));
  return phi;
}

Eigen::MatrixX3d tet_gradients(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T, const Eigen::VectorXd& phi) {
  if (phi.size() != X.rows()) throw std::invalid_argument("phi must have one value per vertex");
  const TetGeometry geo = tet_geometry(X, T);
  Eigen::MatrixX3d g(T.rows(), 3);
  for (Eigen::Index t = 0; t < T.rows(); ++t) {
    Vec3 s = Vec3::Zero();
    for (int a = 0; a < 4; ++a) s += phi(T(t, a)) * geo.grad[t].row(a).transpose();
    g.row(t) = s.transpose();
  }
  return g;
}

}  // namespace emu
