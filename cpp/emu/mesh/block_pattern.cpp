#include "emu/mesh/block_pattern.h"

#include <algorithm>
#include <cstdint>
#include <stdexcept>

namespace emu {

BlockPattern::BlockPattern(const Eigen::MatrixX4i& T, const Eigen::VectorXi& free_index,
                           int num_free, int block_size)
    : bs_(block_size), num_free_(num_free) {
  if (bs_ != 1 && bs_ != 3) throw std::invalid_argument("BlockPattern: block size must be 1 or 3");
  std::vector<int> blk_vi, blk_vj;
  find_blocks(T, free_index, blk_vi, blk_vj);
  lay_out_columns(blk_vi, blk_vj);
  find_incidence(T, free_index);
}

// The stored vertex blocks (vi <= vj) sorted by (vj, vi), and each block's
// contributions (tet, corner pair) in (tet, corner) order.
void BlockPattern::find_blocks(const Eigen::MatrixX4i& T, const Eigen::VectorXi& free_index, std::vector<int>& blk_vi,
                               std::vector<int>& blk_vj) {
  const Eigen::Index m = T.rows();
  struct Entry {
    int vi, vj, t, ab;
  };
  std::vector<Entry> entries;
  entries.reserve(static_cast<size_t>(m) * 10);
  for (Eigen::Index t = 0; t < m; ++t)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        const int vi = free_index(T(t, a)), vj = free_index(T(t, b));
        if (vi < 0 || vj < 0 || vi > vj) continue;
        entries.push_back({vi, vj, static_cast<int>(t), a * 4 + b});
      }
  // Column-major order of blocks, contributions in (tet, corner) order: the
  // entries are made in (t, ab) order, so two stable counting sorts, by vi and
  // then by vj, leave them in (vj, vi, t, ab) order in linear time (a
  // comparison sort is a large share of EMU's setup on big meshes).
  std::vector<Entry> sorted(entries.size());
  std::vector<int> start(static_cast<size_t>(num_free_) + 1);
  auto stable_sort_by = [&](int Entry::*key) {
    std::fill(start.begin(), start.end(), 0);
    for (const Entry& e : entries) ++start[e.*key + 1];
    for (int v = 0; v < num_free_; ++v) start[v + 1] += start[v];
    for (const Entry& e : entries) sorted[start[e.*key]++] = e;
    entries.swap(sorted);
  };
  stable_sort_by(&Entry::vi);
  stable_sort_by(&Entry::vj);
  contrib_ptr_.push_back(0);
  for (size_t e = 0; e < entries.size(); ++e) {
    if (e == 0 || entries[e].vi != entries[e - 1].vi || entries[e].vj != entries[e - 1].vj) {
      if (e > 0) contrib_ptr_.push_back(static_cast<int>(e));
      blk_vi.push_back(entries[e].vi);
      blk_vj.push_back(entries[e].vj);
    }
    contrib_t_.push_back(entries[e].t);
    contrib_ab_.push_back(static_cast<char>(entries[e].ab));
  }
  contrib_ptr_.push_back(static_cast<int>(entries.size()));
  if (entries.empty()) contrib_ptr_.assign(1, 0);
}

// The compressed columns of the blocks' upper triangle and each block's
// position in them.
void BlockPattern::lay_out_columns(const std::vector<int>& blk_vi, const std::vector<int>& blk_vj) {
  const size_t nblk = blk_vi.size();
  // Column counts: block (vi < vj) adds bs rows to each of its bs columns;
  // a diagonal block adds c + 1 rows to its column c.
  const int n = num_free_ * bs_;
  std::vector<int64_t> count(n, 0);
  for (size_t k = 0; k < nblk; ++k)
    for (int c = 0; c < bs_; ++c) count[blk_vj[k] * bs_ + c] += (blk_vi[k] < blk_vj[k]) ? bs_ : c + 1;
  col_ptr_.assign(n + 1, 0);
  int64_t total = 0;
  for (int j = 0; j < n; ++j) {
    total += count[j];
    if (total > INT32_MAX) throw std::runtime_error("BlockPattern: matrix too large for 32-bit indices");
    col_ptr_[j + 1] = static_cast<int>(total);
  }
  row_index_.resize(total);
  block_base_.resize(nblk * bs_);
  block_is_diagonal_.resize(nblk);
  std::vector<int> fill(col_ptr_.begin(), col_ptr_.end() - 1);
  // Blocks are sorted by (vj, vi), so rows within each column come out sorted.
  for (size_t k = 0; k < nblk; ++k) {
    const bool diag = blk_vi[k] == blk_vj[k];
    block_is_diagonal_[k] = diag;
    for (int c = 0; c < bs_; ++c) {
      const int col = blk_vj[k] * bs_ + c;
      block_base_[k * bs_ + c] = fill[col];
      const int nr = diag ? c + 1 : bs_;
      for (int r = 0; r < nr; ++r) row_index_[fill[col]++] = blk_vi[k] * bs_ + r;
    }
  }
}

// Per free vertex, its tet corners (t * 4 + a) in tet order: gather's sums.
void BlockPattern::find_incidence(const Eigen::MatrixX4i& T, const Eigen::VectorXi& free_index) {
  const Eigen::Index m = T.rows();
  std::vector<int> deg(num_free_ + 1, 0);
  for (Eigen::Index t = 0; t < m; ++t)
    for (int a = 0; a < 4; ++a)
      if (free_index(T(t, a)) >= 0) ++deg[free_index(T(t, a)) + 1];
  incidence_ptr_.assign(num_free_ + 1, 0);
  for (int v = 0; v < num_free_; ++v) incidence_ptr_[v + 1] = incidence_ptr_[v] + deg[v + 1];
  incidence_.resize(incidence_ptr_.back());
  std::vector<int> pos(incidence_ptr_.begin(), incidence_ptr_.end() - 1);
  for (Eigen::Index t = 0; t < m; ++t)
    for (int a = 0; a < 4; ++a) {
      const int v = free_index(T(t, a));
      if (v >= 0) incidence_[pos[v]++] = static_cast<int>(t) * 4 + a;
    }
}

void BlockPattern::assemble(const double* element, double* values) const {
  const int ld = 4 * bs_;           // element leading dimension
  const long esize = static_cast<long>(ld) * ld;
  const long nblk = static_cast<long>(block_is_diagonal_.size());
#pragma omp parallel for schedule(static)
  for (long k = 0; k < nblk; ++k) {
    double acc[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};  // bs x bs, column-major
    for (int e = contrib_ptr_[k]; e < contrib_ptr_[k + 1]; ++e) {
      const double* Ke = element + contrib_t_[e] * esize;
      const int a = contrib_ab_[e] / 4, b = contrib_ab_[e] % 4;
      for (int c = 0; c < bs_; ++c)
        for (int r = 0; r < bs_; ++r) acc[r + bs_ * c] += Ke[(a * bs_ + r) + ld * (b * bs_ + c)];
    }
    const bool diag = block_is_diagonal_[k];
    for (int c = 0; c < bs_; ++c) {
      const int nr = diag ? c + 1 : bs_;
      double* dst = values + block_base_[k * bs_ + c];
      for (int r = 0; r < nr; ++r) dst[r] = acc[r + bs_ * c];
    }
  }
}

namespace {
// The gather with its width known at compile time (3: a vertex's x, y, z),
// so the sums are unrolled: a runtime-width loop costs a large share of a CG
// iteration (docs/DESIGN.md, "Tet order and the fit's per-vertex sums"). The
// same order of sums.
template <int W>
void gather_fixed(int num_free, const std::vector<int>& ptr, const std::vector<int>& incidence,
                  const double* corner, double* out) {
#pragma omp parallel for schedule(static)
  for (int v = 0; v < num_free; ++v) {
    double o[W];
    for (int c = 0; c < W; ++c) o[c] = 0.0;
    for (int e = ptr[v]; e < ptr[v + 1]; ++e) {
      const double* src = corner + static_cast<long>(incidence[e]) * W;
      for (int c = 0; c < W; ++c) o[c] += src[c];
    }
    for (int c = 0; c < W; ++c) out[static_cast<long>(v) * W + c] = o[c];
  }
}
}  // namespace

void BlockPattern::gather(const double* corner, int width, double* out) const {
  if (width == 3) return gather_fixed<3>(num_free_, incidence_ptr_, incidence_, corner, out);
  if (width == 1) return gather_fixed<1>(num_free_, incidence_ptr_, incidence_, corner, out);
#pragma omp parallel for schedule(static)
  for (int v = 0; v < num_free_; ++v) {
    double* o = out + static_cast<long>(v) * width;
    for (int c = 0; c < width; ++c) o[c] = 0.0;
    for (int e = incidence_ptr_[v]; e < incidence_ptr_[v + 1]; ++e) {
      const double* src = corner + static_cast<long>(incidence_[e]) * width;
      for (int c = 0; c < width; ++c) o[c] += src[c];
    }
  }
}

}  // namespace emu
