#include "liver_sim/linalg/sparse_pattern.h"

#include <algorithm>

namespace liver_sim {

SparsePattern::SparsePattern(int num_nodes, const Eigen::MatrixX4i& T, const std::vector<std::vector<int>>& groups)
    : num_nodes_(num_nodes) {
  // Node adjacency (each node is its own neighbour), sorted and unique.
  std::vector<std::vector<int>> neighbours(num_nodes);
  for (int i = 0; i < num_nodes; ++i) neighbours[i].push_back(i);
  for (int e = 0; e < T.rows(); ++e)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) neighbours[T(e, a)].push_back(T(e, b));
  for (const std::vector<int>& g : groups)
    for (int a : g) neighbours[a].insert(neighbours[a].end(), g.begin(), g.end());
  for (auto& nb : neighbours) {
    std::sort(nb.begin(), nb.end());
    nb.erase(std::unique(nb.begin(), nb.end()), nb.end());
  }
  const int n = 3 * num_nodes;
  column_start_.assign(n + 1, 0);
  diagonal_.assign(n, -1);
  for (int col = 0; col < n; ++col) {
    const int node = col / 3;
    for (int other : neighbours[node]) {
      if (other > node) break;
      for (int c = 0; c < 3; ++c) {
        const int row = 3 * other + c;
        if (row > col) break;
        if (row == col) diagonal_[col] = static_cast<int>(row_index_.size());
        row_index_.push_back(row);
      }
    }
    column_start_[col + 1] = static_cast<int>(row_index_.size());
  }
}

int SparsePattern::find(int row, int col) const {
  if (row > col) return -1;
  const auto begin = row_index_.begin() + column_start_[col];
  const auto end = row_index_.begin() + column_start_[col + 1];
  const auto it = std::lower_bound(begin, end, row);
  return (it != end && *it == row) ? static_cast<int>(it - row_index_.begin()) : -1;
}

void SparsePattern::append_scatter_map(const int* nodes, int k, std::vector<int>& map) const {
  const int m = 3 * k;
  for (int j = 0; j < m; ++j) {
    const int col = 3 * nodes[j / 3] + j % 3;
    for (int i = 0; i < m; ++i) {
      const int row = 3 * nodes[i / 3] + i % 3;
      map.push_back(row <= col ? find(row, col) : -1);
    }
  }
}

void SparsePattern::multiply(const std::vector<double>& values, const Eigen::VectorXd& x,
                             Eigen::VectorXd& y) const {
  // One thread: each stored entry adds into two places (it stands for its symmetric twin too);
  // a split over threads whose sums did not depend on the thread count would need a second,
  // row-wise index of the pattern, for a product that only the conjugate-gradient strategies use.
  y.setZero(rows());
  for (int col = 0; col < rows(); ++col) {
    for (int k = column_start_[col]; k < column_start_[col + 1]; ++k) {
      const int row = row_index_[k];
      y[row] += values[k] * x[col];
      if (row != col) y[col] += values[k] * x[row];
    }
  }
}

}  // namespace liver_sim
