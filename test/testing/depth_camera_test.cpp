// The synthetic depth camera against closed forms: depth, the z^2 noise law, grazing angles,
// depth edges, occlusion by an instrument, blood, the field of view. Each test names the
// deliberate mutation of the code it guards that it was seen to fail on.
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

TEST(DepthCamera, SeesAFaceHeadOnPixelByPixel) {
  // Mutations seen failing: a footprint growing with z, not z^2 (rays spread by z / f instead
  // of 1 / f); no slack at shared edges (holes along the triangles' diagonals, each ringed by
  // lost pixels).
  Slab s;
  const DepthCamera c = Slab::head_on(0.25);
  const DepthCloud cloud = render_depth_cloud(s.x, s.boundary, {}, c);
  ASSERT_GT(cloud.tissue_points, 10000);
  for (const pcl::PointXYZ& p : cloud.cloud) {
    ASSERT_NEAR(p.z, 0.02, 1e-6);  // float coordinates
    EXPECT_TRUE(p.x >= -1e-6 && p.x <= 0.1 + 1e-6 && p.y >= -1e-6 && p.y <= 0.1 + 1e-6);
  }
  // Head-on, every pixel covers (z / f)^2 of the face: the face's pixels, returned or lost at its
  // border, are its area over that, give or take the ring of pixels its border cuts (the
  // lattice); those at the border number its perimeter over a pixel side. No hole inside.
  const double side = 0.25 / Slab::focal(c);
  EXPECT_NEAR(cloud.tissue_points + cloud.edge_dropped, 0.01 / (side * side), 0.4 / side);
  EXPECT_NEAR(cloud.edge_dropped, 0.4 / side, 8);
  EXPECT_EQ(cloud.grazing_dropped, 0);
  EXPECT_EQ(cloud.instrument_points, 0);
}

TEST(DepthCamera, NoiseGrowsWithTheSquareOfTheDepth) {
  // Mutation seen failing: noise proportional to the depth (the ratio is 2, not 4).
  Slab s;
  std::vector<double> sd;
  for (double height : {0.2, 0.4}) {
    DepthCamera c = Slab::head_on(height);
    c.depth_noise = 1e-3;  // at 0.25 m
    const DepthCloud cloud = render_depth_cloud(s.x, s.boundary, {}, c);
    double sum = 0;
    for (const pcl::PointXYZ& p : cloud.cloud) sum += std::pow(p.z - 0.02, 2);
    sd.push_back(std::sqrt(sum / cloud.cloud.size()));
    // Head-on, the depth error is the height error. Within 3% (tens of thousands of draws).
    EXPECT_NEAR(sd.back(), 1e-3 * std::pow(height / 0.25, 2), 0.03 * 1e-3 * std::pow(height / 0.25, 2));
  }
  EXPECT_NEAR(sd[1] / sd[0], 4.0, 0.15);
}

TEST(DepthCamera, ReturnsNothingAtGrazingAngles) {
  // Mutation seen failing: the incidence test removed (the face returns at 87 degrees).
  Slab s;
  auto top_points = [&](double incidence) {
    DepthCamera c = Slab::head_on(0.25);
    c.target = Eigen::Vector3d(0.05, 0.05, 0.02);  // the top face's centre
    c.eye = c.target + 0.25 * Eigen::Vector3d(std::sin(incidence), 0.0, std::cos(incidence));
    c.up = Eigen::Vector3d::UnitY();
    c.edge_jump = 1.0;  // no depth edge: at 87 degrees neighbouring pixels lie 9 mm apart in depth
    const DepthCloud cloud = render_depth_cloud(s.x, s.boundary, {}, c);
    int n = 0;
    for (const pcl::PointXYZ& p : cloud.cloud) n += on_top(p) && p.x < 0.1 - 1e-6;
    return std::pair{n, cloud.grazing_dropped};
  };
  // 30 degrees: the top face returns (the side faces along y, seen edge-on, do not); 87: the top
  // face is a band of thousands of pixels, none returned.
  const auto [steep, steep_dropped] = top_points(30 * M_PI / 180);
  EXPECT_GT(steep, 10000);
  const auto [grazing, grazing_dropped] = top_points(87 * M_PI / 180);
  EXPECT_EQ(grazing, 0);
  EXPECT_GT(grazing_dropped, 1000 + steep_dropped);
}

TEST(DepthCamera, InstrumentsHideTheTissueAndReturnPointsOfTheirOwn) {
  // Mutation seen failing: instruments left out of the depth buffer (no instrument point, and
  // tissue points seen through the shaft).
  Slab s;
  const InstrumentShaft shaft{Eigen::Vector3d(0.0, 0.05, 0.07), Eigen::Vector3d(0.1, 0.05, 0.07), 0.005};
  const DepthCamera c = Slab::head_on(0.25);
  const DepthCloud cloud = render_depth_cloud(s.x, s.boundary, {shaft}, c);
  EXPECT_GT(cloud.instrument_points, 500);
  int on_shaft = 0;
  for (const pcl::PointXYZ& q : cloud.cloud) {
    const Eigen::Vector3d p(q.x, q.y, q.z);
    const Eigen::Vector2d st = closest_between_segments(c.eye, p, shaft.tip, shaft.trocar);
    const double gap = ((c.eye + st[0] * (p - c.eye)) - (shaft.tip + st[1] * (shaft.trocar - shaft.tip))).norm();
    if (on_top(q)) {
      EXPECT_GT(gap, shaft.radius - 1e-6) << "a tissue point seen through the shaft";
    } else {
      // On the shaft's surface (float coordinates).
      const Eigen::Vector2d axis = closest_between_segments(p, p, shaft.tip, shaft.trocar);
      EXPECT_NEAR((p - (shaft.tip + axis[1] * (shaft.trocar - shaft.tip))).norm(), shaft.radius, 2e-6);
      ++on_shaft;
    }
  }
  EXPECT_EQ(on_shaft, cloud.instrument_points);
}

TEST(DepthCamera, BloodLiesAFilmAboveTheCapsule) {
  // Mutation seen failing: the film's offset taken along the axis instead of along the ray (the
  // heights off the axis are wrong).
  Slab s;
  DepthCamera c = Slab::head_on(0.25);
  c.blood_patches = 1;
  const DepthCloud cloud = render_depth_cloud(s.x, s.boundary, {}, c);
  ASSERT_GT(cloud.blood_points, 100);
  int raised = 0;
  Eigen::Vector3d low = Eigen::Vector3d::Constant(1.0), high = -low;
  for (const pcl::PointXYZ& p : cloud.cloud) {
    const bool blood = std::abs(p.z - 0.022) < 1e-6;
    EXPECT_TRUE(blood || std::abs(p.z - 0.02) < 1e-6) << p.z;
    if (!blood) continue;
    ++raised;
    low = low.cwiseMin(Eigen::Vector3d(p.x, p.y, 0));
    high = high.cwiseMax(Eigen::Vector3d(p.x, p.y, 0));
  }
  EXPECT_EQ(raised, cloud.blood_points);
  EXPECT_LE((high - low).head<2>().maxCoeff(), 2 * c.blood_radius + 1e-3);
}

TEST(DepthCamera, TheFieldOfViewHoldsTheRequestedShareOfTheSurface) {
  // Mutation seen failing: the field of view measured in pixels, not in surface area.
  Slab s;
  DepthCamera c = Slab::head_on(0.25);
  c.visible_fraction = 0.2;
  const DepthCloud cloud = render_depth_cloud(s.x, s.boundary, {}, c);
  const double total = 2 * 0.01 + 4 * 0.1 * 0.02;  // the slab's boundary area
  EXPECT_NEAR(cloud.visible_fraction, 0.2, 0.001);
  // Head-on, the cone is a disc of that area about the face's centre.
  const double radius = std::sqrt(0.2 * total / M_PI), side = 0.25 / Slab::focal(c);
  double farthest = 0;
  for (const pcl::PointXYZ& p : cloud.cloud) farthest = std::max(farthest, std::hypot(p.x - 0.05, p.y - 0.05));
  EXPECT_NEAR(farthest, radius, 2 * side);
}

}  // namespace
}  // namespace liver_sim
