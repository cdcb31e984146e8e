// The surface locator's closest points against brute force.
#include <gtest/gtest.h>

#include <cmath>
#include <pcl/filters/voxel_grid.h>

#include <random>

#include "liver_sim/registration/registration.h"
#include "scenarios.h"
#include "regions.h"
#include "registration/fixtures.h"
#include "geometry/brute_force_distance.h"

namespace liver_sim {
namespace {

// Against brute force, on the phantom as built and after its surface moved (a refit, not a
// rebuild). Killed by a refresh that moves the corners but not the boxes, by a search that
// skips the farther child, by a hint taken for the answer, and by a lower bound that counts
// only the boxes passed over, not the triangles tested (all tried).
TEST(SurfaceLocator, FindsTheClosestTriangleExactly) {
  const Scene scene = load_scene(phantom_scene());
  const LiverModel model(load_scene_mesh(scene), scene);
  const Eigen::MatrixX3i& F = model.boundary();
  Eigen::VectorXd x = model.positions();
  SurfaceLocator locator;
  locator.build(x, F);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.15, 0.15);
  for (int moved = 0; moved < 2; ++moved) {
    if (moved) {  // a twist and a bulge of 2 cm
      for (Eigen::Index i = 0; i < x.size(); i += 3) {
        const Eigen::Vector3d p = x.segment<3>(i);
        const double angle = 3.0 * p.z();
        x.segment<3>(i) = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()) * p +
                          Eigen::Vector3d(0, 0, 0.02 * std::exp(-p.squaredNorm() / 0.005));
      }
      locator.refresh(x, F);
    }
    for (int trial = 0; trial < 300; ++trial) {
      const Eigen::Vector3d p(u(rng), u(rng), 0.5 * u(rng));
      const SurfaceLocator::Hit hit = locator.closest(p);
      ASSERT_NEAR(hit.distance, brute_force_distance(p, x, F), 1e-12) << "point " << p.transpose() << ", moved " << moved;
      // A hint, near or far, only narrows the search.
      const int hint = trial % 2 ? hit.triangle : static_cast<int>(rng() % F.rows());
      EXPECT_EQ(locator.closest(p, std::numeric_limits<double>::infinity(), hint).distance, hit.distance);
      // With a cutoff: exact within it; beyond it no triangle, and a lower bound above it.
      const double cutoff = 0.1 * std::abs(u(rng));
      const SurfaceLocator::Hit gated = locator.closest(p, cutoff);
      if (hit.distance <= cutoff) {
        EXPECT_EQ(gated.distance, hit.distance);
      } else {
        EXPECT_EQ(gated.triangle, -1);
        EXPECT_GT(gated.distance, cutoff);
        EXPECT_LE(gated.distance, hit.distance);
      }
      EXPECT_NEAR((hit.point - p).norm(), hit.distance, 1e-12);
      const Eigen::Vector3d corner = x.segment<3>(3 * F(hit.triangle, 0));
      EXPECT_NEAR((hit.point - corner).dot(hit.normal), 0.0, 1e-12);  // the point lies on its triangle's plane
    }
  }
}

TEST(SurfaceLocator, ACutoffKeepsTheSearchExactWithinIt) {
  // A large triangle (1 m) at z = 0 and, 4 mm above its corner, twenty small ones (1 mm): a
  // point 1 mm above the corner is nearest the large triangle, whose centroid is 0.3 m away,
  // behind the small ones' (about 3 mm away, beyond the 2 mm cutoff). Within the cutoff the hit
  // must be exact; beyond it there is none.
  std::vector<Eigen::Vector3d> nodes = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  std::vector<Eigen::Vector3i> triangles = {{0, 1, 2}};
  for (int k = 0; k < 20; ++k) {
    const Eigen::Vector3d o(0.01 + 0.002 * (k % 5), 0.01 + 0.002 * (k / 5), 0.004);
    const int first = static_cast<int>(nodes.size());
    nodes.insert(nodes.end(), {o, o + Eigen::Vector3d(1e-3, 0, 0), o + Eigen::Vector3d(0, 1e-3, 0)});
    triangles.emplace_back(first, first + 1, first + 2);
  }
  Eigen::VectorXd x(3 * nodes.size());
  for (size_t i = 0; i < nodes.size(); ++i) x.segment<3>(3 * i) = nodes[i];
  Eigen::MatrixX3i F(triangles.size(), 3);
  for (size_t t = 0; t < triangles.size(); ++t) F.row(t) = triangles[t].transpose();
  SurfaceLocator locator;
  locator.build(x, F);
  const SurfaceLocator::Hit near = locator.closest(Eigen::Vector3d(0.015, 0.015, 0.001), 0.002);
  EXPECT_EQ(near.triangle, 0);
  EXPECT_NEAR(near.distance, 0.001, 1e-12);
  const SurfaceLocator::Hit far = locator.closest(Eigen::Vector3d(0.015, 0.015, -0.02), 0.002);
  EXPECT_EQ(far.triangle, -1);
  EXPECT_GT(far.distance, 0.002);
}

}  // namespace
}  // namespace liver_sim
