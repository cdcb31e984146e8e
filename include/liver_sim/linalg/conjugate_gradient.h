// Preconditioned conjugate gradients for symmetric positive definite operators given as
// products, with workspace kept between calls.
#pragma once

#include <Eigen/Core>

#include "liver_sim/linalg/gmres.h"

namespace liver_sim {

class ConjugateGradient {
 public:
  using Operator = Gmres::Operator;  // y = A x, given as a product

  // Returns the iterations; stops when ||b - A x|| <= tolerance ||b|| or after max_iterations.
  // x starts from zero.
  int solve(const Operator& A, const Operator& M_inv, const Eigen::VectorXd& b, Eigen::VectorXd& x,
            double tolerance, int max_iterations);
  double relative_residual() const { return relative_residual_; }

 private:
  Eigen::VectorXd r_, z_, p_, q_;
  double relative_residual_ = 0;
};

}  // namespace liver_sim
