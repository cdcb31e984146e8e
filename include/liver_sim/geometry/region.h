// Geometric regions that select nodes or boundary triangles of a mesh (in the rest shape).
#pragma once

#include <Eigen/Core>

namespace liver_sim {

struct Region {
  enum class Kind { Box, Sphere, Disc };
  Kind kind = Kind::Box;
  Eigen::Vector3d min = Eigen::Vector3d::Zero();     // box corner (m)
  Eigen::Vector3d max = Eigen::Vector3d::Zero();     // box corner (m)
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  // sphere or disc centre (m)
  double radius = 0.0;                               // sphere or disc outer radius (m)
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ(); // disc axis (unit after validation)
  double inner_radius = 0.0;  // disc: points closer to the axis are excluded (an annulus) (m)
  double depth = -1.0;        // disc: max distance from the disc plane (m); <0: 0.05 * radius

  // A disc selects only boundary entities; box and sphere select volume nodes too.
  bool boundary_only() const { return kind == Kind::Disc; }
  bool contains(const Eigen::Vector3d& p) const;
};

}  // namespace liver_sim
