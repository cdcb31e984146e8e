// The broad phase of contact detection: the boundary triangles that may come near an
// instrument, and the material points sampled on a triangle.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>

#include "liver_sim/contact/instrument_shape.h"
#include "liver_sim/contact/surface_point.h"

namespace liver_sim {

// The boundary triangles that may come within `reach` of the instrument of options o at pose,
// at positions x, by a bound on their distance (the distance function grows no faster than the
// distance): visit(t, a, b, c) with the triangle's corners.
template <typename Visit>
void near_triangles(const Eigen::MatrixX3i& boundary, const InstrumentOptions& o, const Eigen::Isometry3d& pose,
                    const Eigen::VectorXd& x, double reach, const Visit& visit) {
  const InstrumentShape& shape = shape_of(o.type);
  for (int t = 0; t < boundary.rows(); ++t) {
    const Eigen::Vector3d a = x.segment<3>(3 * boundary(t, 0)), b = x.segment<3>(3 * boundary(t, 1)),
                          c = x.segment<3>(3 * boundary(t, 2));
    const Eigen::Vector3d centre = (a + b + c) / 3;
    const double radius = std::sqrt(std::max({(a - centre).squaredNorm(), (b - centre).squaredNorm(), (c - centre).squaredNorm()}));
    if (shape.distance(o, pose, centre).distance - radius >= reach) continue;
    visit(t, a, b, c);
  }
}

// The samples of boundary triangle t at most `spacing` apart in the rest shape X (infinite: its
// nodes), each a SurfacePoint given to visit().
template <typename Visit>
void sample_triangle(const Eigen::MatrixX3i& boundary, const Eigen::VectorXd& X, int t, double spacing,
                     const Visit& visit) {
  std::array<int, 3> v = {boundary(t, 0), boundary(t, 1), boundary(t, 2)};
  std::sort(v.begin(), v.end());
  // Divisions of each edge (shared with the neighbour across it: the same rest length) and of
  // the triangle (its longest edge's).
  const auto divisions = [&](int a, int b) {
    const double length = (X.segment<3>(3 * a) - X.segment<3>(3 * b)).norm();
    return std::isfinite(spacing) ? std::max(1, static_cast<int>(std::ceil(length / spacing))) : 1;
  };
  const int edge_divisions[3] = {divisions(v[0], v[1]), divisions(v[1], v[2]), divisions(v[0], v[2])};
  SurfacePoint s;
  for (int j = 0; j < 3; ++j) {
    s.nodes = {v[j], -1, -1};
    s.weights = Eigen::Vector3d(1, 0, 0);
    s.count = 1;
    s.sample = 0;
    visit(s);
  }
  const int ends[3][2] = {{0, 1}, {1, 2}, {0, 2}};
  for (int e = 0; e < 3; ++e)
    for (int i = 1; i < edge_divisions[e]; ++i) {
      const double w = static_cast<double>(i) / edge_divisions[e];
      s.nodes = {v[ends[e][0]], v[ends[e][1]], -1};
      s.weights = Eigen::Vector3d(1 - w, w, 0);
      s.count = 2;
      s.sample = i;
      visit(s);
    }
  const int n = *std::max_element(edge_divisions, edge_divisions + 3);
  s.nodes = v;
  s.count = 3;
  for (int i = 1; i < n; ++i)
    for (int j = 1; i + j < n; ++j) {
      s.weights = Eigen::Vector3d(n - i - j, i, j) / n;
      s.sample = i * n + j;
      visit(s);
    }
}

}  // namespace liver_sim
