// Box meshes and boundaries: counts, volume, orientation, symmetry, bad sizes, mesh checks.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>

#include "liver_sim/geometry/mesh.h"
#include "liver_sim/io/mesh_io.h"
#include "geometry/mesh_checks.h"

namespace liver_sim {
namespace {

TEST(BoxMesh, CountsVolumeAndOrientation) {
  const Eigen::Vector3d size(0.015, 0.012, 0.009);
  const TetMesh m = make_box_mesh(size, {8, 6, 4});
  EXPECT_EQ(m.V.rows(), 9 * 7 * 5);
  EXPECT_EQ(m.T.rows(), 5 * 8 * 6 * 4);
  EXPECT_TRUE(check_mesh(m).ok());
  EXPECT_NEAR(total_volume(m), size.prod(), 1e-12 * size.prod());
}

TEST(BoxMesh, BoundaryIsTheBoxSurfaceFacingOutward) {
  const Eigen::Vector3d size(0.015, 0.015, 0.015);
  const TetMesh m = make_box_mesh(size, {8, 8, 8});
  EXPECT_EQ(m.V.rows(), 729);
  EXPECT_EQ(m.T.rows(), 2560);
  const Eigen::MatrixX3i B = boundary_triangles(m.T);
  EXPECT_EQ(B.rows(), 2 * 6 * 64);  // conforming: two triangles per boundary quad, none inside
  for (int f = 0; f < B.rows(); ++f) {
    const Eigen::Vector3d c = (m.V.row(B(f, 0)) + m.V.row(B(f, 1)) + m.V.row(B(f, 2))).transpose() / 3;
    const Eigen::Vector3d n = area_vector(m.V, B.row(f)).normalized();
    const Eigen::Vector3d d = c - size / 2;
    int axis;
    d.cwiseAbs().maxCoeff(&axis);
    ASSERT_NEAR(std::abs(d[axis]), size[axis] / 2, 1e-12) << "triangle " << f << " is not on a face";
    ASSERT_NEAR(n[axis], d[axis] > 0 ? 1.0 : -1.0, 1e-12) << "triangle " << f << " faces inward";
  }
  expect_closed_outward_boundary(m);
}

TEST(BoxMesh, MirrorSymmetricAboutMidPlanes) {
  const Eigen::Vector3d size(0.015, 0.015, 0.015);
  const TetMesh m = make_box_mesh(size, {4, 4, 4});
  auto centroids = [&](int axis) {
    std::vector<std::array<long long, 3>> c;
    for (int t = 0; t < m.T.rows(); ++t) {
      Eigen::Vector3d p = Eigen::Vector3d::Zero();
      for (int k = 0; k < 4; ++k) p += m.V.row(m.T(t, k)).transpose() / 4;
      if (axis >= 0) p[axis] = size[axis] - p[axis];
      c.push_back({std::llround(p.x() * 1e9), std::llround(p.y() * 1e9), std::llround(p.z() * 1e9)});
    }
    std::sort(c.begin(), c.end());
    return c;
  };
  const auto original = centroids(-1);
  for (int axis = 0; axis < 3; ++axis) EXPECT_EQ(centroids(axis), original) << "axis " << axis;
}

TEST(BoxMesh, RejectsBadSizes) {
  EXPECT_THROW(make_box_mesh({0.01, 0, 0.01}, {2, 2, 2}), MeshError);
  EXPECT_THROW(make_box_mesh({0.01, 0.01, std::nan("")}, {2, 2, 2}), MeshError);
  EXPECT_THROW(make_box_mesh({0.01, 0.01, 0.01}, {2, 0, 2}), MeshError);
}

TEST(Boundary, SingleAndTwoTetrahedra) {
  TetMesh m;
  m.V.resize(5, 3);
  m.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1;
  m.T.resize(1, 4);
  m.T << 0, 1, 2, 3;
  EXPECT_EQ(boundary_triangles(m.T).rows(), 4);
  expect_closed_outward_boundary(m);
  m.T.resize(2, 4);
  m.T << 0, 1, 2, 3, 1, 2, 3, 4;
  if (signed_volume(m.V, m.T, 1) < 0) std::swap(m.T(1, 2), m.T(1, 3));
  EXPECT_EQ(boundary_triangles(m.T).rows(), 6);
  expect_closed_outward_boundary(m);
}

TEST(MeshCheck, ReportsInvertedAndDegenerateIndices) {
  TetMesh m = make_box_mesh({1, 1, 1}, {1, 1, 2});
  std::swap(m.T(3, 0), m.T(3, 1));  // inverted
  m.T(7, 3) = m.T(7, 0);            // repeated node
  const MeshCheck c = check_mesh(m);
  EXPECT_EQ(c.inverted, std::vector<int>{3});
  EXPECT_EQ(c.degenerate, std::vector<int>{7});
  try {
    validate_mesh(m, "m");
    FAIL() << "validate_mesh accepted a bad mesh";
  } catch (const MeshError& e) {
    EXPECT_NE(std::string(e.what()).find("7"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace liver_sim
