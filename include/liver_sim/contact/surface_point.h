// A material point of the tissue's surface, ROS-free: where a contact acts or a grasper holds.
#pragma once

#include <Eigen/Core>
#include <array>

namespace liver_sim {

// On a boundary triangle (three nodes), an edge (two) or at a node, with barycentric weights;
// nodes in increasing order and `sample` numbering the points of one triangle or edge, so that
// a point found from two triangles has one description.
struct SurfacePoint {
  std::array<int, 3> nodes{-1, -1, -1};
  Eigen::Vector3d weights = Eigen::Vector3d::Zero();
  int count = 0;
  int sample = 0;
  Eigen::Vector3d at(const Eigen::VectorXd& x) const;
  // The point of triangle `nodes` with weights w (weights below 1e-9 dropped).
  static SurfacePoint on_triangle(const Eigen::Vector3i& nodes, const Eigen::Vector3d& w);
};

}  // namespace liver_sim
