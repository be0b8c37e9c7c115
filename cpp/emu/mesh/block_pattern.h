#pragma once
// Deterministic, allocation-free assembly over a fixed sparsity pattern.
//
// A symmetric matrix is assembled from one (4 bs) x (4 bs) element matrix per
// tet (bs = 1 for the scalar ACAP Laplacian, 3 for position Hessians) over the
// free vertices (free_index[v] >= 0). Only the upper triangle is stored, in
// compressed-column form, as CHOLMOD wants it (stype = 1). The pattern and, for
// every stored vertex block, the ordered list of element blocks that sum into
// it are computed once; assembly is a parallel gather in that fixed order, so
// results are bitwise reproducible for any thread count.
#include <vector>

#include <Eigen/Core>

namespace emu {

class BlockPattern {
 public:
  /// T           #T by 4 vertex indices
  /// free_index  #V free-vertex index of each vertex, -1 if the vertex is not an unknown
  /// num_free    number of free vertices
  /// block_size  unknowns per vertex (1 or 3)
  BlockPattern(const Eigen::MatrixX4i& T, const Eigen::VectorXi& free_index, int num_free,
               int block_size);

  int rows() const { return num_free_ * bs_; }
  long nnz() const { return static_cast<long>(row_index_.size()); }
  const std::vector<int>& col_ptr() const { return col_ptr_; }
  const std::vector<int>& row_index() const { return row_index_; }

  /// element  #T blocks of (4 bs)^2 doubles, each column-major (local row 3a+i for bs = 3)
  /// values   nnz() doubles, overwritten
  void assemble(const double* element, double* values) const;

  /// Sum per-corner vectors into per-free-vertex vectors.
  /// corner  #T blocks of 4 * width doubles (corner a at a * width)
  /// out     num_free * width doubles (vertex-major), overwritten
  void gather(const double* corner, int width, double* out) const;

 private:
  void find_blocks(const Eigen::MatrixX4i& T, const Eigen::VectorXi& free_index, std::vector<int>& blk_vi,
                   std::vector<int>& blk_vj);
  void lay_out_columns(const std::vector<int>& blk_vi, const std::vector<int>& blk_vj);
  void find_incidence(const Eigen::MatrixX4i& T, const Eigen::VectorXi& free_index);

  int bs_, num_free_;
  std::vector<int> col_ptr_, row_index_;
  // Stored vertex blocks (row vertex <= column vertex): position in values of
  // entry (bs*vi + r, bs*vj + c) is base_[blk*bs + c] + r.
  std::vector<int> block_base_;
  std::vector<char> block_is_diagonal_;
  std::vector<int> contrib_ptr_;  // per block: range into contrib_
  std::vector<int> contrib_t_;    // tet
  std::vector<char> contrib_ab_;  // a * 4 + b: element rows of corner a, columns of corner b
  std::vector<int> incidence_ptr_, incidence_;  // per free vertex: t * 4 + a
};

}  // namespace emu
