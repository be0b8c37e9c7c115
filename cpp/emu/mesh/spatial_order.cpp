#include "emu/mesh/spatial_order.h"

#include <algorithm>
#include <cstdint>
#include <stdexcept>

namespace emu {

namespace {
// A 10-bit integer with two zero bits after each of its bits.
uint32_t spread_bits(uint32_t q) {
  q = (q | (q << 16)) & 0x030000FFu;
  q = (q | (q << 8)) & 0x0300F00Fu;
  q = (q | (q << 4)) & 0x030C30C3u;
  return (q | (q << 2)) & 0x09249249u;
}
}  // namespace

std::vector<int> spatial_order(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T) {
  const Eigen::Index m = T.rows();
  if (m > 0 && (T.minCoeff() < 0 || T.maxCoeff() >= X.rows()))
    throw std::invalid_argument("spatial_order: a tet's vertex id lies outside [0, #V)");
  Eigen::MatrixX3d c(m, 3);
  for (Eigen::Index t = 0; t < m; ++t)
    c.row(t) = 0.25 * (X.row(T(t, 0)) + X.row(T(t, 1)) + X.row(T(t, 2)) + X.row(T(t, 3)));
  std::vector<int> order(m);
  if (m == 0) return order;
  const Eigen::RowVector3d lo = c.colwise().minCoeff();
  const double extent = (c.colwise().maxCoeff() - lo).maxCoeff();
  std::vector<uint32_t> code(m);
  for (Eigen::Index t = 0; t < m; ++t) {
    uint32_t key = 0;
    for (int d = 0; d < 3; ++d) {
      // (c - lo) / extent lies in [0, 1]: no overflow for any extent
      const double q = extent > 0 ? std::min((c(t, d) - lo(d)) / extent * 1024.0, 1023.0) : 0.0;
      key |= spread_bits(static_cast<uint32_t>(q)) << d;
    }
    code[t] = key;
  }
  // LSD radix sort, three 10-bit digits: stable, linear in #T.
  std::vector<int> in(m), out(m);
  for (Eigen::Index t = 0; t < m; ++t) in[t] = static_cast<int>(t);
  std::vector<int> count(1025);
  for (int shift = 0; shift < 30; shift += 10) {
    std::fill(count.begin(), count.end(), 0);
    for (int t : in) ++count[((code[t] >> shift) & 1023u) + 1];
    for (int k = 0; k < 1024; ++k) count[k + 1] += count[k];
    for (int t : in) out[count[(code[t] >> shift) & 1023u]++] = t;
    in.swap(out);
  }
  return in;
}

}  // namespace emu
