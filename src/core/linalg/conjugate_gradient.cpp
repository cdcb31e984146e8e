#include "liver_sim/linalg/conjugate_gradient.h"

#include <cmath>

namespace liver_sim {

int ConjugateGradient::solve(const Operator& A, const Operator& M_inv, const Eigen::VectorXd& b,
                             Eigen::VectorXd& x, double tolerance, int max_iterations, Clock::time_point deadline) {
  x.setZero(b.size());
  const double b_norm = b.norm();
  relative_residual_ = 0;
  out_of_time_ = false;
  if (b_norm == 0) return 0;
  r_ = b;
  M_inv(r_, z_);
  p_ = z_;
  double rz = r_.dot(z_);
  int k = 0;
  while (k < max_iterations) {
    A(p_, q_);
    const double alpha = rz / p_.dot(q_);
    x += alpha * p_;
    r_ -= alpha * q_;
    ++k;
    relative_residual_ = r_.norm() / b_norm;
    if (relative_residual_ <= tolerance || !std::isfinite(relative_residual_)) break;
    if (Clock::now() > deadline) {
      out_of_time_ = true;
      break;
    }
    M_inv(r_, z_);
    const double rz_next = r_.dot(z_);
    p_ = z_ + (rz_next / rz) * p_;
    rz = rz_next;
  }
  return k;
}

}  // namespace liver_sim
