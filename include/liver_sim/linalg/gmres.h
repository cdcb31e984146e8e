// Right-preconditioned GMRES (no restart) with workspace kept between calls. Solves A x = b for
// a general (non-symmetric) operator given only as products, preconditioned by M^-1 ~ A^-1.
#pragma once

#include <Eigen/Core>
#include <chrono>
#include <functional>

namespace liver_sim {

class Gmres {
 public:
  using Operator = std::function<void(const Eigen::VectorXd& in, Eigen::VectorXd& out)>;
  using Clock = std::chrono::steady_clock;

  // Returns the number of iterations; stops when ||b - A x|| <= tolerance ||b|| (estimated
  // from the Arnoldi recurrence), after max_iterations, or after the first iteration that ends
  // past the deadline (one always runs). x starts from zero; stopped early, it is the iterate
  // built so far, which minimises the residual over the subspace built: never worse than zero.
  int solve(const Operator& A, const Operator& M_inv, const Eigen::VectorXd& b, Eigen::VectorXd& x,
            double tolerance, int max_iterations, Clock::time_point deadline = Clock::time_point::max());

  // Relative residual estimate at the end of the last solve.
  double relative_residual() const { return relative_residual_; }
  // The last solve stopped at the deadline short of its tolerance.
  bool out_of_time() const { return out_of_time_; }

 private:
  Eigen::MatrixXd V_, Z_, H_;  // Krylov basis, preconditioned basis, Hessenberg matrix
  Eigen::VectorXd g_, cs_, sn_, w_, in_;
  double relative_residual_ = 0;
  bool out_of_time_ = false;
};

}  // namespace liver_sim
