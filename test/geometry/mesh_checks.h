// Shared by the mesh tests: volume and a closed, outward boundary.
#pragma once

#include <gtest/gtest.h>

#include <map>

#include "liver_sim/geometry/mesh.h"

namespace liver_sim {

inline double total_volume(const TetMesh& m) {
  double v = 0;
  for (int t = 0; t < m.T.rows(); ++t) v += signed_volume(m.V, m.T, t);
  return v;
}

inline Eigen::Vector3d area_vector(const Eigen::MatrixX3d& V, const Eigen::Vector3i& f) {
  return 0.5 * (V.row(f[1]) - V.row(f[0])).transpose().cross((V.row(f[2]) - V.row(f[0])).transpose());
}

// Closed, consistently outward surface: every edge shared by exactly two triangles in opposite
// directions, area vectors summing to zero, and the divergence-theorem volume equal to the sum
// of the tetrahedron volumes.
inline void expect_closed_outward_boundary(const TetMesh& m) {
  const Eigen::MatrixX3i B = boundary_triangles(m.T);
  std::map<std::pair<int, int>, int> directed;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double area = 0, volume = 0;
  for (int f = 0; f < B.rows(); ++f) {
    for (int k = 0; k < 3; ++k) ++directed[{B(f, k), B(f, (k + 1) % 3)}];
    const Eigen::Vector3d a = area_vector(m.V, B.row(f));
    sum += a;
    area += a.norm();
    const Eigen::Vector3d c = (m.V.row(B(f, 0)) + m.V.row(B(f, 1)) + m.V.row(B(f, 2))).transpose() / 3;
    volume += c.dot(a) / 3;
  }
  for (const auto& [edge, n] : directed) {
    ASSERT_EQ(n, 1) << "edge " << edge.first << "-" << edge.second << " used twice in one direction";
    ASSERT_EQ(directed.count({edge.second, edge.first}), 1u) << "open edge";
  }
  EXPECT_LE(sum.norm(), 1e-9 * area);
  EXPECT_NEAR(volume, total_volume(m), 1e-9 * total_volume(m));
}

}  // namespace liver_sim
