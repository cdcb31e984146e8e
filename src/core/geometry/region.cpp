#include "liver_sim/geometry/region.h"

#include <Eigen/Geometry>
#include <cmath>

namespace liver_sim {

bool Region::contains(const Eigen::Vector3d& p) const {
  switch (kind) {
    case Kind::Box: {
      // Faces included, with a tolerance that absorbs rounding of generated coordinates.
      const Eigen::Array3d tol = 1e-9 * (1.0 + (max - min).array().abs());
      return ((p - min).array() >= -tol).all() && ((max - p).array() >= -tol).all();
    }
    case Kind::Sphere:
      return (p - center).norm() <= radius * (1 + 1e-9);
    case Kind::Disc: {
      const Eigen::Vector3d n = normal.normalized();
      const Eigen::Vector3d d = p - center;
      const double height = n.dot(d);
      const double r = (d - height * n).norm();
      const double tol = 1e-9 * radius;
      const double max_depth = depth < 0 ? 0.05 * radius : depth;
      return std::abs(height) <= max_depth + tol && r >= inner_radius - tol && r <= radius + tol;
    }
  }
  return false;
}

}  // namespace liver_sim
