#pragma once
// A structured test and benchmark mesh: a bar of unit hexes, six Kuhn tets
// each, pinned at z = 0, one muscle with fibres along z.
#include <algorithm>
#include <array>
#include <vector>

#include <Eigen/Core>

#include "emu/mesh/tet_geometry.h"
#include "emu/model/model.h"

namespace emu {

// nx x nx x nz hexes of unit size, six Kuhn tets each; pinned at z = 0; one muscle along z.
inline Model bar(int nx, int nz) {
  Model m;
  auto vid = [&](int i, int j, int k) { return (i * (nx + 1) + j) * (nz + 1) + k; };
  m.rest.resize((nx + 1) * (nx + 1) * (nz + 1), 3);
  for (int i = 0; i <= nx; ++i)
    for (int j = 0; j <= nx; ++j)
      for (int k = 0; k <= nz; ++k) m.rest.row(vid(i, j, k)) << i, j, k;
  std::vector<std::array<int, 4>> tets;
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < nx; ++j)
      for (int k = 0; k < nz; ++k)
        for (auto& p : perms) {
          int c[3] = {0, 0, 0};
          std::array<int, 4> t;
          t[0] = vid(i, j, k);
          for (int s = 0; s < 3; ++s) {
            c[p[s]] = 1;
            t[s + 1] = vid(i + c[0], j + c[1], k + c[2]);
          }
          tets.push_back(t);
        }
  m.tets.resize(tets.size(), 4);
  for (size_t t = 0; t < tets.size(); ++t)
    for (int a = 0; a < 4; ++a) m.tets(t, a) = tets[t][a];
  const Eigen::VectorXd vol = signed_volumes(m.rest, m.tets);
  for (Eigen::Index t = 0; t < m.tets.rows(); ++t)
    if (vol(t) < 0) std::swap(m.tets(t, 1), m.tets(t, 2));
  const Eigen::Index nt = m.tets.rows();
  const double E = 6e4, nu = 0.45;
  m.mu = Eigen::VectorXd::Constant(nt, E / (2 * (1 + nu)));
  m.lambda = Eigen::VectorXd::Constant(nt, E * nu / ((1 + nu) * (1 - 2 * nu)));
  m.density = Eigen::VectorXd::Ones(nt);
  m.acap_weight = Eigen::VectorXd::Ones(nt);
  m.fiber = Eigen::MatrixX3d::Zero(nt, 3);
  m.fiber.col(2).setOnes();
  m.muscle = Eigen::VectorXi::Zero(nt);
  m.num_muscles = 1;
  std::vector<int> pins;
  for (int i = 0; i <= nx; ++i)
    for (int j = 0; j <= nx; ++j) pins.push_back(vid(i, j, 0));
  std::sort(pins.begin(), pins.end());
  m.pinned = Eigen::Map<Eigen::VectorXi>(pins.data(), pins.size());
  return m;
}

// The bar's load: its one muscle at activation a.
inline LoadCase bar_load(double a) {
  LoadCase l;
  l.activation = Eigen::VectorXd::Constant(1, a);
  return l;
}
}  // namespace emu
