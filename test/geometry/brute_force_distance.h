// Shared by the tests of closest points: the distance to a surface by brute force.
#pragma once

#include <Eigen/Core>

#include <limits>

#include "liver_sim/geometry/closest_points.h"

namespace liver_sim {

// The closest point by brute force over every triangle.
inline double brute_force_distance(const Eigen::Vector3d& p, const Eigen::VectorXd& x, const Eigen::MatrixX3i& F) {
  double best = std::numeric_limits<double>::infinity();
  for (int t = 0; t < F.rows(); ++t) {
    const Eigen::Vector3d a = x.segment<3>(3 * F(t, 0)), b = x.segment<3>(3 * F(t, 1)), c = x.segment<3>(3 * F(t, 2));
    const Eigen::Vector3d w = closest_on_triangle(p, a, b, c);
    best = std::min(best, (p - (w[0] * a + w[1] * b + w[2] * c)).norm());
  }
  return best;
}

}  // namespace liver_sim
