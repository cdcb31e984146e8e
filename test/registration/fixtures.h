// Shared by the registration tests: the phantom at rest and clouds of its surface, a cantilever.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <string>
#include <vector>

#include "liver_sim/registration/registration.h"
#include "regions.h"

namespace liver_sim {

inline std::string phantom_scene() { return std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/liver_phantom.yaml"; }

// The phantom at rest, and clouds made of its own surface.
struct RestPhantom {
  Scene scene = load_scene(phantom_scene());
  LiverModel model{load_scene_mesh(scene), scene};
  RegistrationOptions options = scene.registration;
  // A point on boundary triangle t, `offset` along its outward normal.
  Eigen::Vector3d on_triangle(int t, double offset) const {
    const Eigen::MatrixX3i& F = model.boundary();
    const Eigen::Vector3d a = model.positions().segment<3>(3 * F(t, 0)), b = model.positions().segment<3>(3 * F(t, 1)),
                          c = model.positions().segment<3>(3 * F(t, 2));
    return (a + b + c) / 3 + offset * (b - a).cross(c - a).normalized();
  }
  double area(int t) const {
    const Eigen::MatrixX3i& F = model.boundary();
    const Eigen::Vector3d a = model.positions().segment<3>(3 * F(t, 0)), b = model.positions().segment<3>(3 * F(t, 1)),
                          c = model.positions().segment<3>(3 * F(t, 2));
    return 0.5 * (b - a).cross(c - a).norm();
  }
  // The triangles whose centroid lies above height z (the top of the right lobe and more).
  std::vector<int> above(double z) const {
    std::vector<int> t;
    for (int k = 0; k < model.boundary().rows(); ++k)
      if (on_triangle(k, 0).z() > z) t.push_back(k);
    return t;
  }
};

inline pcl::PointCloud<pcl::PointXYZ> cloud_of(const std::vector<Eigen::Vector3d>& points) {
  pcl::PointCloud<pcl::PointXYZ> c;
  for (const Eigen::Vector3d& p : points) c.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  return c;
}

// A cantilever 4 x 1 x 1 cm clamped at x = 0 under gravity, with two probes.
inline Scene cantilever(double young_modulus) {
  Scene s;
  s.mesh.box_size = Eigen::Vector3d(0.04, 0.01, 0.01);
  s.mesh.box_divisions = Eigen::Vector3i(8, 2, 2);
  s.parenchyma.young_modulus = young_modulus;
  s.solver.tolerance = 1e-11;
  s.solver.max_iterations = 50;
  s.fixed.push_back(box({-1, -1, -1}, {1e-9, 1, 1}));
  s.loads.push_back(LoadOptions::gravity({0, 0, -9.81}));
  s.probes.push_back({"tip", Eigen::Vector3d(0.037, 0.005, 0.005)});
  s.probes.push_back({"middle", Eigen::Vector3d(0.021, 0.004, 0.006)});
  return s;
}

}  // namespace liver_sim
