// The tracked stylus's coverage against the stadium a stroke reaches.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <random>
#include <thread>

#include "depth_camera.h"
#include "liver_sim/geometry/closest_points.h"
#include "liver_sim/registration/registration.h"
#include "liver_sim/registration/target_uncertainty.h"
#include "liver_sim/registration/uncertainty_worker.h"
#include "regions.h"
#include "scenarios.h"
#include "stylus.h"
#include "testing/slab.h"

namespace liver_sim {
namespace {

TEST(Stylus, CoverageOfAStrokeIsTheAreaWithinReach) {
  // A straight stroke of points 1 mm apart across the slab's top face covers the stadium within
  // `reach` of it (2 r L + pi r^2), not the area of the triangles it crosses; and a sweep asked
  // for a coverage reaches it as the same measure counts it. Mutation seen failing: the
  // samples within 2 x reach counted (2.4 times the stadium's share).
  Slab s;
  const double reach = 0.01, length = 0.06;
  pcl::PointCloud<pcl::PointXYZ> stroke;
  for (double t = 0; t <= length + 1e-9; t += 1e-3) stroke.push_back(pcl::PointXYZ(0.02 + t, 0.05, 0.02));
  const double total = 2 * 0.1 * 0.1 + 4 * 0.1 * 0.02;
  const double stadium = 2 * reach * length + M_PI * reach * reach;
  EXPECT_NEAR(area_coverage(s.x, s.boundary, stroke, reach), stadium / total, 0.1 * stadium / total);

  StylusSweep sweep;
  sweep.anterior = Eigen::Vector3d::UnitZ();
  sweep.coverage = 0.2;
  sweep.noise = 0;
  const StylusData data = swab_surface(s.x, s.boundary, sweep);
  EXPECT_GE(data.coverage, 0.2);
  EXPECT_NEAR(area_coverage(s.x, s.boundary, data.cloud, sweep.reach, 7), data.coverage, 0.03);
  for (const pcl::PointXYZ& p : data.cloud) EXPECT_NEAR(p.z, 0.02, 1e-6);  // the anterior (top) face only
}

}  // namespace
}  // namespace liver_sim
