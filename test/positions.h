// Shared by the core tests: vertices (one per row) as the stacked position vector the model uses.
#pragma once

#include <Eigen/Core>

namespace liver_sim {

inline Eigen::VectorXd flatten(const Eigen::MatrixX3d& V) {
  Eigen::VectorXd x(3 * V.rows());
  for (int i = 0; i < V.rows(); ++i) x.segment<3>(3 * i) = V.row(i).transpose();
  return x;
}

}  // namespace liver_sim
