// Shared by the tests of the synthetic sensors: a slab seen head-on.
#pragma once

#include <pcl/point_types.h>

#include <cmath>

#include "depth_camera.h"
#include "liver_sim/geometry/mesh.h"
#include "positions.h"

namespace liver_sim {

// A 10 x 10 cm slab, 2 cm thick, its top face at z = 0.02, seen head-on from `height` above it.
struct Slab {
  TetMesh mesh = make_box_mesh(Eigen::Vector3d(0.1, 0.1, 0.02), Eigen::Vector3i(5, 5, 1));
  Eigen::MatrixX3i boundary = boundary_triangles(mesh.T);
  Eigen::VectorXd x = flatten(mesh.V);
  static DepthCamera head_on(double height) {
    DepthCamera c;
    c.eye = Eigen::Vector3d(0.05, 0.05, 0.02 + height);
    c.target = Eigen::Vector3d(0.05, 0.05, 0.0);
    c.up = Eigen::Vector3d::UnitY();
    c.visible_fraction = 1.0;
    c.depth_noise = 0.0;
    c.lateral_noise = 0.0;
    c.blood_patches = 0;
    return c;
  }
  // The camera's focal length (pixels) and the side of a pixel's footprint at depth z (m).
  static double focal(const DepthCamera& c) { return 0.5 * c.width / std::tan(0.5 * c.horizontal_fov); }
};

inline bool on_top(const pcl::PointXYZ& p) { return std::abs(p.z - 0.02) < 1e-6 && p.x > -1e-6 && p.x < 0.1 + 1e-6; }

}  // namespace liver_sim
