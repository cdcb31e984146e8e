// Sparse Cholesky (CHOLMOD, supernodal with a fill-reducing ordering) for symmetric positive
// definite matrices given as an upper triangle in compressed columns. The symbolic analysis is
// done once per pattern; each factorize() reuses it; solves reuse CHOLMOD's workspace.
#pragma once

#include <cholmod.h>

#include <Eigen/Core>
#include <vector>

namespace liver_sim {

class CholmodSolver {
 public:
  CholmodSolver();
  ~CholmodSolver();
  CholmodSolver(const CholmodSolver&) = delete;
  CholmodSolver& operator=(const CholmodSolver&) = delete;

  // Symbolic analysis of the n x n pattern. The arrays must outlive the solver's use of them.
  void analyze(int n, const std::vector<int>& column_start, const std::vector<int>& row_index);

  // Numeric factorisation with values laid out as the analysed pattern. Returns false (and
  // keeps no factor) when the matrix is not positive definite or has non-finite entries.
  bool factorize(const std::vector<double>& values);

  // x = A^-1 b with the last successful factor.
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x);
  // X = A^-1 B, all columns in one pass over the factor.
  void solve(const Eigen::MatrixXd& B, Eigen::MatrixXd& X);

  bool analyzed() const { return factor_ != nullptr; }
  bool factorized() const { return factorized_; }
  // Nonzeros of the factor (fill), after analysis.
  double factor_nonzeros() const;
  // Symbolic analyses and numeric factorisations done so far (to check what work was skipped).
  int analyses() const { return analyses_; }
  int factorizations() const { return factorizations_; }

 private:
  void solve_columns(const double* b, long columns);  // into x_
  cholmod_common common_;
  cholmod_sparse A_{};       // views the caller's arrays
  cholmod_factor* factor_ = nullptr;
  cholmod_dense* x_ = nullptr;
  cholmod_dense* Y_ = nullptr;  // solve workspaces kept between calls
  cholmod_dense* E_ = nullptr;
  bool factorized_ = false;
  int analyses_ = 0;
  int factorizations_ = 0;
};

}  // namespace liver_sim
