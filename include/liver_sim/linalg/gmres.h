// Right-preconditioned GMRES (no restart) with workspace kept between calls. Solves A x = b for
// a general (non-symmetric) operator given only as products, preconditioned by M^-1 ~ A^-1.
#pragma once

#include <Eigen/Core>
#include <functional>

namespace liver_sim {

class Gmres {
 public:
  using Operator = std::function<void(const Eigen::VectorXd& in, Eigen::VectorXd& out)>;

  // Returns the number of iterations; stops when ||b - A x|| <= tolerance ||b|| (estimated
  // from the Arnoldi recurrence) or after max_iterations. x starts from zero.
  int solve(const Operator& A, const Operator& M_inv, const Eigen::VectorXd& b, Eigen::VectorXd& x,
            double tolerance, int max_iterations);

  // Relative residual estimate at the end of the last solve.
  double relative_residual() const { return relative_residual_; }

 private:
  Eigen::MatrixXd V_, Z_, H_;  // Krylov basis, preconditioned basis, Hessenberg matrix
  Eigen::VectorXd g_, cs_, sn_, w_, in_;
  double relative_residual_ = 0;
};

}  // namespace liver_sim
