// The capsule's CST membrane against closed forms: rigid motions, in-plane patch tests, the
// explicit CST stiffness.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <array>
#include <random>

#include "liver_sim/model/corotational_tetra.h"
#include "liver_sim/model/membrane_cst.h"
#include "liver_sim/geometry/mesh.h"
#include "model/element_fixtures.h"

namespace liver_sim {
namespace {

// --- CST membrane ---

TEST(MembraneRotation, RigidMotionOfDeformedStateRotatesForces) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(3, 3, 3));
  MembraneCST m(mesh.V, boundary_triangles(mesh.T), capsule());
  const Eigen::VectorXd x = flatten(mesh.V) + random_field(3 * mesh.V.rows(), 0.05 * kSize, 3);
  const Eigen::VectorXd f = membrane_forces(m, x);
  const Eigen::Matrix3d Q = some_rotation();
  const Eigen::VectorXd f_moved = membrane_forces(m, transform(x, Q, Eigen::Vector3d(-0.3, 0.1, 0.2)));
  ASSERT_GT(f.norm(), 0.0);
  EXPECT_LE((f_moved - transform(f, Q, Eigen::Vector3d::Zero())).norm(), 1e-9 * f.norm());
}

TEST(MembraneRotation, RigidMotionOfRestStateGivesZeroForce) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(3, 3, 3));
  const CapsuleOptions c = capsule();
  MembraneCST m(mesh.V, boundary_triangles(mesh.T), c);
  const Eigen::VectorXd x = transform(flatten(mesh.V), some_rotation(), Eigen::Vector3d(1.0, 2.0, -0.5));
  const double h = kSize / 3;  // force scale: unit strain along one edge, E t h
  EXPECT_LE(membrane_forces(m, x).cwiseAbs().maxCoeff(), 1e-9 * c.young_modulus * c.thickness * h);
}

// The top face of a box is a planar membrane; an in-plane affine field (then a rigid rotation
// out of the plane) gives the same strain everywhere and equilibrium at interior face nodes.
TEST(MembranePatch, InPlaneAffineFieldGivesConstantStrainAndZeroInteriorResidual) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(4, 4, 4));
  const Eigen::MatrixX3i all = boundary_triangles(mesh.T);
  std::vector<int> top;
  for (int f = 0; f < all.rows(); ++f)
    if (mesh.V(all(f, 0), 2) > kSize - 1e-12 && mesh.V(all(f, 1), 2) > kSize - 1e-12 &&
        mesh.V(all(f, 2), 2) > kSize - 1e-12)
      top.push_back(f);
  ASSERT_EQ(top.size(), 32u);
  Eigen::MatrixX3i F(top.size(), 3);
  for (size_t k = 0; k < top.size(); ++k) F.row(k) = all.row(top[k]);
  MembraneCST m(mesh.V, F, capsule());

  Eigen::Matrix3d A = Eigen::Matrix3d::Identity();
  A.topLeftCorner<2, 2>() << 1.15, 0.08, -0.05, 0.92;
  const Eigen::Matrix3d Q = some_rotation();
  const Eigen::VectorXd x = transform(flatten(mesh.V), Q * A, Eigen::Vector3d(0.0, 0.01, 0.0));
  const Eigen::VectorXd f = membrane_forces(m, x);
  const Eigen::JacobiSVD<Eigen::Matrix2d> svd(A.topLeftCorner<2, 2>(), Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix2d stretch =
      svd.matrixV() * svd.singularValues().asDiagonal() * svd.matrixV().transpose();
  // Each triangle's strain is in its own local axes: compare invariants (trace, determinant).
  const Eigen::Matrix2d expected = stretch - Eigen::Matrix2d::Identity();
  for (int e = 0; e < m.size(); ++e) {
    const Eigen::Matrix2d s = m.corotated_strain(e, x);
    ASSERT_NEAR(s.trace(), expected.trace(), 1e-12) << "triangle " << e;
    ASSERT_NEAR(s.determinant(), expected.determinant(), 1e-12) << "triangle " << e;
  }
  double interior_max = 0;
  for (int i = 0; i < mesh.V.rows(); ++i) {
    const Eigen::Vector3d p = mesh.V.row(i);
    if (p.z() > kSize - 1e-12 && p.x() > 1e-12 && p.x() < kSize - 1e-12 && p.y() > 1e-12 &&
        p.y() < kSize - 1e-12)
      interior_max = std::max(interior_max, f.segment<3>(3 * i).norm());
  }
  ASSERT_GT(f.cwiseAbs().maxCoeff(), 0.0);
  EXPECT_LE(interior_max, 1e-9 * f.cwiseAbs().maxCoeff());
}

// The frames (four triangles at a time, and the remainder one by one) are the polar rotation of
// each triangle's in-plane gradient: orthonormal, in the current plane, and turning the gradient
// into a symmetric stretch. A flattened triangle gets a finite frame.
TEST(MembraneRotation, FramesAreThePolarRotationOfTheInPlaneGradient) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(2, 2, 1));
  const Eigen::MatrixX3i all = boundary_triangles(mesh.T);
  const Eigen::MatrixX3i F = all.topRows(all.rows() - 2);  // a box's boundary count is a multiple of 4
  ASSERT_NE(F.rows() % 4, 0);
  MembraneCST m(mesh.V, F, capsule());
  const Eigen::VectorXd X = flatten(mesh.V);
  m.update_rotations(X);
  const std::vector<Eigen::Matrix<double, 3, 2>> rest = m.frames();  // the rest axes
  Eigen::VectorXd x = transform(X + random_field(X.size(), 0.1 * kSize, 31), some_rotation(), Eigen::Vector3d::Zero());
  const int flat = 5;  // node 1 of triangle 5 moved onto node 0
  x.segment<3>(3 * F(flat, 1)) = x.segment<3>(3 * F(flat, 0));
  m.update_rotations(x);
  const auto edges = [&](const Eigen::VectorXd& y, int e) {
    Eigen::Matrix<double, 3, 2> D;
    D << y.segment<3>(3 * F(e, 1)) - y.segment<3>(3 * F(e, 0)), y.segment<3>(3 * F(e, 2)) - y.segment<3>(3 * F(e, 0));
    return D;
  };
  for (int e = 0; e < m.size(); ++e) {
    const Eigen::Matrix<double, 3, 2>& A = m.frames()[e];
    if (e == flat || (F.row(e).array() == F(flat, 1)).any()) {
      ASSERT_TRUE(A.allFinite()) << "triangle " << e;
      continue;
    }
    const Eigen::Matrix<double, 3, 2> D = edges(x, e);
    const Eigen::Vector3d normal = D.col(0).cross(D.col(1)).normalized();
    const Eigen::Matrix2d G = A.transpose() * D * (rest[e].transpose() * edges(X, e)).inverse();
    ASSERT_LE((A.transpose() * A - Eigen::Matrix2d::Identity()).cwiseAbs().maxCoeff(), 1e-14) << "triangle " << e;
    ASSERT_LE((A.transpose() * normal).cwiseAbs().maxCoeff(), 1e-14) << "triangle " << e;
    ASSERT_LE(std::abs(G(0, 1) - G(1, 0)), 1e-13 * G.norm()) << "triangle " << e;
    ASSERT_GT(G.trace(), 0) << "triangle " << e;
  }
}

// The membrane stiffness against K = h A B^T D B with the explicit CST B matrix of the
// formulation notes, in the triangle's own 2D coordinates.
TEST(MembraneStiffness, MatchesExplicitCstFormula) {
  Eigen::MatrixX3d V(3, 3);
  V << 0.001, 0.002, 0.003, 0.011, 0.004, 0.001, 0.004, 0.010, 0.006;
  Eigen::MatrixX3i F(1, 3);
  F << 0, 1, 2;
  const CapsuleOptions c = capsule();
  MembraneCST m(V, F, c);
  const Eigen::VectorXd rest = Eigen::Map<const Eigen::VectorXd>(Eigen::MatrixXd(V.transpose()).data(), 9);
  m.update_rotations(rest);
  Matrix9d K;
  m.element_tangent(0, K);

  // Local axes: first edge and its in-plane normal.
  const Eigen::Vector3d e1 = (V.row(1) - V.row(0)).normalized();
  const Eigen::Vector3d n = (V.row(1) - V.row(0)).cross(V.row(2) - V.row(0)).normalized();
  const Eigen::Vector3d e2 = n.cross(e1);
  double x[3], y[3];
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d d = (V.row(i) - V.row(0)).transpose();
    x[i] = e1.dot(d);
    y[i] = e2.dot(d);
  }
  const double area = 0.5 * ((x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]));
  const double y23 = y[1] - y[2], y31 = y[2] - y[0], y12 = y[0] - y[1];
  const double x32 = x[2] - x[1], x13 = x[0] - x[2], x21 = x[1] - x[0];
  Eigen::Matrix<double, 3, 6> B;
  B << y23, 0, y31, 0, y12, 0, 0, x32, 0, x13, 0, x21, x32, y23, x13, y31, x21, y12;
  B /= 2 * area;
  const double E = c.young_modulus, nu = c.poisson_ratio;
  Eigen::Matrix3d D;
  D << 1, nu, 0, nu, 1, 0, 0, 0, (1 - nu) / 2;
  D *= E / (1 - nu * nu);
  const Eigen::Matrix<double, 6, 6> K2 = c.thickness * area * B.transpose() * D * B;
  Eigen::Matrix<double, 9, 6> T = Eigen::Matrix<double, 9, 6>::Zero();
  for (int i = 0; i < 3; ++i) {
    T.block<3, 1>(3 * i, 2 * i) = e1;
    T.block<3, 1>(3 * i, 2 * i + 1) = e2;
  }
  const Matrix9d expected = T * K2 * T.transpose();
  EXPECT_LE((K - expected).norm(), 1e-12 * expected.norm());
}

// Vertex order must not matter for the membrane (its rotation comes from the polar
// decomposition, not from the first edge).
TEST(MembraneRotation, ForcesDoNotDependOnVertexOrder) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(2, 2, 2));
  const Eigen::MatrixX3i F = boundary_triangles(mesh.T);
  Eigen::MatrixX3i G(F.rows(), 3);
  for (int f = 0; f < F.rows(); ++f) G.row(f) << F(f, 1), F(f, 2), F(f, 0);  // same orientation
  MembraneCST a(mesh.V, F, capsule()), b(mesh.V, G, capsule());
  const Eigen::VectorXd x = flatten(mesh.V) + random_field(3 * mesh.V.rows(), 0.1 * kSize, 5);
  const Eigen::VectorXd fa = membrane_forces(a, x), fb = membrane_forces(b, x);
  EXPECT_LE((fa - fb).norm(), 1e-9 * fa.norm());
}

// The membrane's matrix-free product against its tangent times the vector.
TEST(MembraneStiffness, TangentProductMatchesTheTangent) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(2, 2, 2));
  MembraneCST m(mesh.V, boundary_triangles(mesh.T), capsule());
  const Eigen::VectorXd x = transform(flatten(mesh.V) + random_field(3 * mesh.V.rows(), 0.05 * kSize, 12), some_rotation(),
                                      Eigen::Vector3d::Zero());
  m.update_rotations(x);
  const Eigen::VectorXd v = random_field(x.size(), 1.0, 13);
  for (int e = 0; e < m.size(); ++e) {
    Matrix9d K;
    m.element_tangent(e, K);
    Vector9d ve, out;
    for (int k = 0; k < 3; ++k) ve.segment<3>(3 * k) = v.segment<3>(3 * m.triangles()(e, k));
    m.tangent_product(e, m.frames()[e], v, out);
    const Vector9d expected = K * ve;
    ASSERT_LE((out - expected).norm(), 1e-12 * expected.norm()) << "triangle " << e;
  }
}

}  // namespace
}  // namespace liver_sim
