// The support a cloud must show before it acts, against the model at rest. Each test names
// the deliberate mutation of the code it guards that it was seen to fail on.
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
#include "registration/fixtures.h"

namespace liver_sim {
namespace {

TEST(CloudSupport, OnePointAboveTheSurfaceIsRefusedAndMovesNothing) {
  // Mutation seen failing: the min_points test removed (the point pulls a spike 8 mm up and
  // the fit reads 0.01 mm).
  RestPhantom p;
  SurfaceRegistration registration(p.model, p.options);
  const Eigen::VectorXd before = p.model.positions();
  try {
    registration.register_cloud(cloud_of({p.on_triangle(p.above(0.05).front(), 0.01)}));
    FAIL() << "a one-point cloud was registered";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("min_points"), std::string::npos) << e.what();
  }
  EXPECT_EQ((p.model.positions() - before).norm(), 0.0);
  EXPECT_TRUE(p.model.surface_targets().empty());
  EXPECT_TRUE(registration.cloud_springs().empty());
}

TEST(CloudSupport, AFewSquareCentimetresAreNotEnough) {
  // Mutation seen failing: the min_coverage test removed.
  RestPhantom p;
  p.options.voxel_size = 0;
  std::vector<Eigen::Vector3d> patch;
  const int t = p.above(0.05).front();
  for (int k = 0; k < 200; ++k) patch.push_back(p.on_triangle(t, 0.002 + 1e-5 * k));  // one triangle, 200 points
  SurfaceRegistration registration(p.model, p.options);
  try {
    registration.register_cloud(cloud_of(patch));
    FAIL() << "a cloud on one triangle was registered";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("min_coverage"), std::string::npos) << e.what();
  }
}

TEST(CloudSupport, SpringsScaleWithTheCoverageAndTheFitCountsEveryPoint) {
  // Mutations seen failing: the stiffness not scaled by the coverage (the springs' total is
  // `stiffness`); rms_all over the accepted points only (it reads 0.3 mm, not 6 mm).
  RestPhantom p;
  p.options.voxel_size = 0;
  p.options.trim_fraction = 0;
  p.options.correspondence_updates = 1;  // the frame's coverage and springs are those at rest
  const std::vector<int> top = p.above(0.05);  // the top of the right lobe, convex
  // One point per triangle, 0.3 mm out; the triangles they cover found by brute force.
  std::vector<Eigen::Vector3d> points;
  for (int t : top) points.push_back(p.on_triangle(t, 3e-4));
  std::vector<char> covered(p.model.boundary().rows(), 0);
  for (const Eigen::Vector3d& q : points) {
    int best = -1;
    double nearest = 1e9;
    for (int t = 0; t < p.model.boundary().rows(); ++t) {
      Eigen::Matrix3d v;
      for (int j = 0; j < 3; ++j) v.col(j) = p.model.positions().segment<3>(3 * p.model.boundary()(t, j));
      const double d = (q - v * closest_on_triangle(q, v.col(0), v.col(1), v.col(2))).norm();
      if (d < nearest) nearest = d, best = t;
    }
    covered[best] = 1;
  }
  double covered_area = 0, total = 0;
  for (int t = 0; t < p.model.boundary().rows(); ++t) total += p.area(t), covered_area += covered[t] ? p.area(t) : 0.0;
  const double coverage = covered_area / total;
  ASSERT_GT(coverage, p.options.min_coverage);
  ASSERT_LT(coverage, p.options.full_coverage);
  // A quarter more, deep inside (the tumour's centre, over 15 mm from the surface): outliers.
  const size_t inliers = points.size();
  for (size_t k = 0; k < inliers / 3; ++k) points.push_back(Eigen::Vector3d(-0.05, -0.02, 0.005 + 1e-5 * k));
  SurfaceRegistration registration(p.model, p.options);
  const RegistrationFrame f = registration.register_cloud(cloud_of(points));
  EXPECT_NEAR(f.coverage, coverage, 1e-9);
  EXPECT_NEAR(f.inlier_fraction, static_cast<double>(inliers) / points.size(), 1e-12);
  double springs = 0;
  for (const SurfaceTarget& s : p.model.surface_targets()) springs += s.stiffness;
  EXPECT_NEAR(springs, p.options.stiffness * coverage / p.options.full_coverage, 1e-9 * p.options.stiffness);
  // The outliers count at max_distance; the inliers' 0.3 mm shrinks as the surface follows.
  const double outlier_share = 1.0 - f.inlier_fraction;
  EXPECT_GT(f.rms_all, std::sqrt(outlier_share) * p.options.max_distance);
  EXPECT_LT(f.rms_all, std::sqrt(outlier_share * std::pow(p.options.max_distance, 2) + 1e-7));
  EXPECT_LT(f.rms, 3e-4);
}

}  // namespace
}  // namespace liver_sim
