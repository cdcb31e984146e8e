// Sparse Cholesky (CHOLMOD, supernodal with a fill-reducing ordering) for symmetric positive
// definite matrices given as an upper triangle in compressed columns. The symbolic analysis is
// done once per pattern; each factorize() reuses it; solves reuse CHOLMOD's workspace.
//
// With A = P^T L L^T P, a solve is a forward half z = L^-1 P b and a backward half
// x = P^T L^-T z. The forward half of a unit vector is nonzero only on the path of its column
// up the supernodal elimination tree; such sparse columns give entries of A^-1 as inner
// products, e_a^T A^-1 e_b = (L^-1 P e_a) . (L^-1 P e_b), at the cost of the paths alone.
// Knows nothing of the physics. It runs on the calling thread: constructing one sets OpenBLAS
// to one thread and allows no active OpenMP level, process-wide (cholmod_solver.cpp says why).
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

  // Exchanges the numeric factors of two solvers analysed on the same pattern (a factorisation
  // done on another thread handed over); each counts it as a factorisation. Not thread-safe.
  void swap_factor(CholmodSolver& other);

  // x = A^-1 b with the last successful factor.
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x);
  // X = A^-1 B, all columns in one pass over the factor.
  void solve(const Eigen::MatrixXd& B, Eigen::MatrixXd& X);

  // The two halves of solve(b, x): z = L^-1 P b, then x = P^T L^-T z.
  void forward(const Eigen::VectorXd& b, Eigen::VectorXd& z);
  void backward(const Eigen::VectorXd& z, Eigen::VectorXd& x);

  // L^-1 P e_i for the unit vector of row i: its values on the supernodes of its path up the
  // elimination tree, leaf first (the rest is zero). Needs a factor.
  struct SparseColumn {
    std::vector<int> supernodes;  // leaf to root
    std::vector<int> offsets;     // where each supernode's values start in `values`
    Eigen::VectorXd values;
  };
  void forward_unit(int i, SparseColumn& y);
  // a . b: over the supernodes the two paths share (from their meeting point to the root).
  double dot(const SparseColumn& a, const SparseColumn& b) const;
  // a . z and z += s a, for z in the space of forward()'s output.
  double dot(const SparseColumn& a, const Eigen::VectorXd& z) const;
  void add(const SparseColumn& a, double s, Eigen::VectorXd& z) const;

  bool analyzed() const { return factor_ != nullptr; }
  bool factorized() const { return factorized_; }
  // Nonzeros of the factor (fill), after analysis.
  double factor_nonzeros() const;
  // Symbolic analyses and numeric factorisations done so far (to check what work was skipped).
  int analyses() const { return analyses_; }
  int factorizations() const { return factorizations_; }

 private:
  void solve_columns(const double* b, long columns);  // into x_
  // A dense vector of the factor's size viewing `data`.
  cholmod_dense view(const double* data) const;
  cholmod_common common_;
  cholmod_sparse A_{};       // views the caller's arrays
  cholmod_factor* factor_ = nullptr;
  cholmod_dense* x_ = nullptr;
  cholmod_dense* Y_ = nullptr;  // solve workspaces kept between calls
  cholmod_dense* E_ = nullptr;
  cholmod_dense* half_ = nullptr;  // forward()/backward() results
  Eigen::VectorXd permuted_;       // P b, or L^-T z
  std::vector<int> inverse_perm_;  // position in the factor of each row of A
  std::vector<int> supernode_of_;  // supernode of each column of L
  Eigen::VectorXd unit_work_;      // forward_unit's right-hand side, zero between calls
  Eigen::VectorXd below_;          // forward_unit: a supernode's update of the rows below it
  bool factorized_ = false;
  int analyses_ = 0;
  int factorizations_ = 0;
};

}  // namespace liver_sim
