#pragma once
// y = A x for a symmetric n x n matrix given by its upper triangle in
// compressed-column form (the layout BlockPattern assembles and CHOLMOD
// factorises): each stored a_ij (i <= j) adds a_ij x_j to y_i and, off the
// diagonal, a_ij x_i to y_j. One sequential pass over the entries (the
// scatter to y_j is not thread-safe; the pass reads each entry once).
namespace emu {

inline void symmetric_upper_product(int n, const int* col_ptr, const int* row_index, const double* values,
                                    const double* x, double* y) {
  for (int j = 0; j < n; ++j) y[j] = 0.0;
  for (int j = 0; j < n; ++j) {
    const double xj = x[j];
    double yj = 0.0;
    const int end = col_ptr[j + 1];
    for (int k = col_ptr[j]; k < end; ++k) {
      const int i = row_index[k];
      const double a = values[k];
      y[i] += a * xj;
      if (i != j) yj += a * x[i];
    }
    y[j] += yj;
  }
}

}  // namespace emu
