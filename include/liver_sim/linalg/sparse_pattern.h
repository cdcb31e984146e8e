// Fixed sparsity pattern of the global stiffness matrix (3 DOFs per node, coupled through
// tetrahedra and through any further groups of nodes, such as the nodes a beam couples), stored as the upper triangle in compressed columns, the layout CHOLMOD reads.
// Built once per topology; element matrices are added through precomputed scatter maps so that
// assembly writes values in place with no search and no allocation.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace liver_sim {

class SparsePattern {
 public:
  SparsePattern() = default;
  SparsePattern(int num_nodes, const Eigen::MatrixX4i& T, const std::vector<std::vector<int>>& groups = {});

  int rows() const { return 3 * num_nodes_; }
  int nonzeros() const { return static_cast<int>(row_index_.size()); }
  const std::vector<int>& column_start() const { return column_start_; }
  const std::vector<int>& row_index() const { return row_index_; }

  // Index into the value array of entry (row, col) with row <= col; -1 if not in the pattern.
  int find(int row, int col) const;
  int diagonal(int dof) const { return diagonal_[dof]; }

  // Scatter map of an element with `k` nodes: for local entry (i, j) of its 3k x 3k matrix, at
  // position i + 3k j (column-major), the value index, or -1 where the global entry lies in the
  // lower triangle (covered by its symmetric twin). Appends to `map`.
  void append_scatter_map(const int* nodes, int k, std::vector<int>& map) const;

  // y = A x for the symmetric matrix whose upper triangle is `values`.
  void multiply(const std::vector<double>& values, const Eigen::VectorXd& x,
                Eigen::VectorXd& y) const;

 private:
  int num_nodes_ = 0;
  std::vector<int> column_start_;
  std::vector<int> row_index_;
  std::vector<int> diagonal_;
};

// Adds a dense element matrix into `values` through its scatter map.
template <typename Matrix>
inline void scatter_add(const Matrix& Ke, const int* map, std::vector<double>& values) {
  const double* a = Ke.data();
  for (int k = 0; k < Matrix::SizeAtCompileTime; ++k)
    if (map[k] >= 0) values[map[k]] += a[k];
}

}  // namespace liver_sim
