// Preconditioned conjugate gradients for symmetric positive definite operators given as
// products, with workspace kept between calls.
#pragma once

#include <Eigen/Core>

#include "liver_sim/linalg/gmres.h"

namespace liver_sim {

class ConjugateGradient {
 public:
  using Operator = Gmres::Operator;  // y = A x, given as a product
  using Clock = Gmres::Clock;

  // Returns the iterations; stops when ||b - A x|| <= tolerance ||b||, after max_iterations, or
  // after the first iteration that ends past the deadline (one always runs). x starts from zero;
  // stopped early, it is the iterate so far, which lowers the energy 1/2 x.Ax - b.x from zero's.
  int solve(const Operator& A, const Operator& M_inv, const Eigen::VectorXd& b, Eigen::VectorXd& x,
            double tolerance, int max_iterations, Clock::time_point deadline = Clock::time_point::max());
  double relative_residual() const { return relative_residual_; }
  bool out_of_time() const { return out_of_time_; }  // the last solve stopped at the deadline short of its tolerance

 private:
  Eigen::VectorXd r_, z_, p_, q_;
  double relative_residual_ = 0;
  bool out_of_time_ = false;
};

}  // namespace liver_sim
