#include "liver_sim/linalg/gmres.h"

#include <Eigen/Dense>
#include <cmath>

namespace liver_sim {

int Gmres::solve(const Operator& A, const Operator& M_inv, const Eigen::VectorXd& b,
                 Eigen::VectorXd& x, double tolerance, int max_iterations, Clock::time_point deadline) {
  const Eigen::Index n = b.size();
  const int m = max_iterations;
  if (V_.rows() != n || V_.cols() < m + 1) {
    V_.resize(n, m + 1);
    Z_.resize(n, m);
  }
  H_.setZero(m + 1, m);
  g_.setZero(m + 1);
  cs_.setZero(m);
  sn_.setZero(m);
  x.setZero(n);
  const double beta = b.norm();
  relative_residual_ = 0;
  out_of_time_ = false;
  if (beta == 0) return 0;
  V_.col(0) = b / beta;
  g_[0] = beta;
  int k = 0;
  while (k < m) {
    in_ = V_.col(k);
    M_inv(in_, w_);
    Z_.col(k) = w_;
    in_ = w_;
    A(in_, w_);
    // Modified Gram-Schmidt.
    for (int i = 0; i <= k; ++i) {
      H_(i, k) = w_.dot(V_.col(i));
      w_ -= H_(i, k) * V_.col(i);
    }
    H_(k + 1, k) = w_.norm();
    if (H_(k + 1, k) > 0) V_.col(k + 1) = w_ / H_(k + 1, k);
    // Apply earlier Givens rotations, then one that zeroes H(k+1, k).
    for (int i = 0; i < k; ++i) {
      const double t = cs_[i] * H_(i, k) + sn_[i] * H_(i + 1, k);
      H_(i + 1, k) = -sn_[i] * H_(i, k) + cs_[i] * H_(i + 1, k);
      H_(i, k) = t;
    }
    const double r = std::hypot(H_(k, k), H_(k + 1, k));
    if (r == 0) break;  // singular operator: keep the iterate built so far
    cs_[k] = H_(k, k) / r;
    sn_[k] = H_(k + 1, k) / r;
    H_(k, k) = r;
    H_(k + 1, k) = 0;
    g_[k + 1] = -sn_[k] * g_[k];
    g_[k] = cs_[k] * g_[k];
    ++k;
    relative_residual_ = std::abs(g_[k]) / beta;
    if (relative_residual_ <= tolerance) break;
    if (Clock::now() > deadline) {
      out_of_time_ = true;
      break;
    }
  }
  const Eigen::VectorXd y =
      H_.topLeftCorner(k, k).triangularView<Eigen::Upper>().solve(g_.head(k));
  x = Z_.leftCols(k) * y;
  return k;
}

}  // namespace liver_sim
