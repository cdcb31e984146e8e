// Closest points on triangles and segments against dense sampling.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <thread>

#include "liver_sim/geometry/closest_points.h"
#include "liver_sim/contact/contact_solver.h"
#include "liver_sim/simulation/liver_model.h"
#include "regions.h"

namespace liver_sim {
namespace {

// The closest point of a triangle to a point, against dense sampling: where a probe is deepest in
// a triangle (and, in the registration, a cloud point's correspondence on the surface).
// Kills K13 (the closest point on a triangle's first edge with swapped weights), which the
// segment test below does not see (its edge candidates find the right point).
TEST(ClosestOnTriangle, MatchesDenseSampling) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), c(u(rng), u(rng), u(rng));
    const Eigen::Vector3d p = 2 * Eigen::Vector3d(u(rng), u(rng), u(rng));
    const Eigen::Vector3d w = closest_on_triangle(p, a, b, c);
    EXPECT_NEAR(w.sum(), 1.0, 1e-12);
    EXPECT_GE(w.minCoeff(), -1e-12);
    const double d = (p - (w[0] * a + w[1] * b + w[2] * c)).norm();
    // No sample of the triangle is closer (a 200 x 200 barycentric grid).
    double sampled = std::numeric_limits<double>::infinity();
    for (int i = 0; i <= 200; ++i)
      for (int j = 0; i + j <= 200; ++j) {
        const double s = i / 200.0, t = j / 200.0;
        sampled = std::min(sampled, (p - ((1 - s - t) * a + s * b + t * c)).norm());
      }
    EXPECT_LE(d, sampled + 1e-12);
    EXPECT_GE(d, sampled - 0.02);  // the grid's spacing bounds how far it can be off
  }
}

// A triangle without area (two corners at one place, or three on a line) is its edges: weights
// in [0, 1] summing to 1 at the closest point of the segments. Killed by the edges' and the
// face's divisions left unguarded (tried: the first trial fails).
TEST(ClosestOnTriangle, ATriangleWithoutAreaIsItsEdges) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  auto on_segment = [](const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    const Eigen::Vector3d e = b - a;
    const double t = e.squaredNorm() > 0 ? std::clamp(e.dot(p - a) / e.squaredNorm(), 0.0, 1.0) : 0.0;
    return (p - a - t * e).norm();
  };
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), p = 2 * Eigen::Vector3d(u(rng), u(rng), u(rng));
    const double s = u(rng);
    for (const Eigen::Vector3d& c : {Eigen::Vector3d(b), Eigen::Vector3d(a + s * (b - a))}) {
      const Eigen::Vector3d w = closest_on_triangle(p, a, b, c);
      ASSERT_TRUE(w.allFinite()) << "trial " << trial;
      EXPECT_NEAR(w.sum(), 1.0, 1e-12);
      EXPECT_GE(w.minCoeff(), -1e-12);
      EXPECT_LE(w.maxCoeff(), 1 + 1e-12);
      const double d = (p - (w[0] * a + w[1] * b + w[2] * c)).norm();
      EXPECT_NEAR(d, std::min({on_segment(p, a, b), on_segment(p, b, c), on_segment(p, a, c)}), 1e-9) << "trial " << trial;
    }
  }
}

// The closest pair between a segment (a shaft's axis) and a triangle, against dense sampling of
// both: no sampled pair is closer, and the pair found is no farther than the sampling's spacing
// allows. It sets how deep an appearing shaft sits in the surface (how far it retreats before it
// comes in), and, through the segment ends' closest points on the triangle
// (closest_on_triangle), where a probe is deepest in a triangle and a grasper's fallback hold.
// Kills K14 (a segment against an edge, with the weights on the wrong edge).
TEST(ClosestPoints, SegmentTriangleMatchesDenseSampling) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  constexpr int kSegment = 100, kTriangle = 60;  // samples along the segment and per triangle edge
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), c(u(rng), u(rng), u(rng));
    const Eigen::Vector3d p0 = 2 * Eigen::Vector3d(u(rng), u(rng), u(rng)), p1 = 2 * Eigen::Vector3d(u(rng), u(rng), u(rng));
    const SegmentTriangle found = closest_segment_triangle(p0, p1, a, b, c);
    const Eigen::Vector3d& w = found.weights;
    ASSERT_NEAR(w.sum(), 1.0, 1e-12);
    ASSERT_GE(w.minCoeff(), -1e-12);
    ASSERT_GE(found.s, 0.0);
    ASSERT_LE(found.s, 1.0);
    const double d = (p0 + found.s * (p1 - p0) - (w[0] * a + w[1] * b + w[2] * c)).norm();
    double sampled = std::numeric_limits<double>::infinity();
    for (int k = 0; k <= kSegment; ++k) {
      const Eigen::Vector3d q = p0 + (static_cast<double>(k) / kSegment) * (p1 - p0);
      for (int i = 0; i <= kTriangle; ++i)
        for (int j = 0; i + j <= kTriangle; ++j) {
          const double s = static_cast<double>(i) / kTriangle, t = static_cast<double>(j) / kTriangle;
          sampled = std::min(sampled, (q - ((1 - s - t) * a + s * b + t * c)).norm());
        }
    }
    EXPECT_LE(d, sampled + 1e-12) << "trial " << trial;
    // Samples lie within half a spacing of every point: segment <= 4 sqrt(3) / 100 / 2, triangle
    // edges <= 2 sqrt(3) / 60.
    EXPECT_GE(d, sampled - 0.1) << "trial " << trial;
  }
}

}  // namespace
}  // namespace liver_sim
