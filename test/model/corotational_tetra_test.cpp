// The corotational tetrahedron against closed forms: rigid motions, patch tests, the Voigt
// stiffness, finite differences, the polar rotation.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <array>
#include <limits>
#include <random>

#include "liver_sim/model/corotational_tetra.h"
#include "liver_sim/model/membrane_cst.h"
#include "liver_sim/geometry/mesh.h"
#include "model/element_fixtures.h"

namespace liver_sim {
namespace {

class TetraRotation : public ::testing::TestWithParam<RotationMethod> {};

TEST_P(TetraRotation, RigidMotionOfDeformedStateRotatesForces) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(3, 3, 3));
  CorotationalTetra tets(mesh.V, mesh.T, material(GetParam()));
  const Eigen::VectorXd x = flatten(mesh.V) + random_field(3 * mesh.V.rows(), 0.05 * kSize, 1);
  const Eigen::VectorXd f = tet_forces(tets, x);
  const Eigen::Matrix3d Q = some_rotation();
  const Eigen::VectorXd f_moved = tet_forces(tets, transform(x, Q, Eigen::Vector3d(0.2, -0.1, 0.05)));
  const Eigen::VectorXd expected = transform(f, Q, Eigen::Vector3d::Zero());
  ASSERT_GT(f.norm(), 0.0);
  EXPECT_LE((f_moved - expected).norm(), 1e-9 * f.norm());
}

TEST_P(TetraRotation, RigidMotionOfRestStateGivesZeroForce) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(3, 3, 3));
  CorotationalTetra tets(mesh.V, mesh.T, material(GetParam()));
  const Eigen::VectorXd x = transform(flatten(mesh.V), some_rotation(), Eigen::Vector3d(1.0, 2.0, -0.5));
  // Force scale: unit strain over one element face, E h^2.
  const double h = kSize / 3;
  EXPECT_LE(tet_forces(tets, x).cwiseAbs().maxCoeff(), 1e-9 * kE * h * h);
}

// Any affine deformation: every element has the same corotated strain and interior nodes are
// in equilibrium (the polar rotation is exact for every F, not only small ones).
TEST(TetraPatch, AffineFieldGivesConstantStrainAndZeroInteriorResidual) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(4, 4, 4));
  CorotationalTetra tets(mesh.V, mesh.T, material(RotationMethod::Polar));
  Eigen::Matrix3d A;
  A << 1.2, 0.1, -0.05, 0.03, 0.9, 0.2, -0.1, 0.04, 1.1;
  const Eigen::Matrix3d F = some_rotation() * A;
  const Eigen::VectorXd x = transform(flatten(mesh.V), F, Eigen::Vector3d(0.01, 0.0, 0.0));
  const Eigen::VectorXd f = tet_forces(tets, x);
  // Polar: R^T F = sqrt(F^T F), so the corotated strain is U - I with U the right stretch.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d expected =
      svd.matrixV() * svd.singularValues().asDiagonal() * svd.matrixV().transpose() -
      Eigen::Matrix3d::Identity();
  for (int e = 0; e < tets.size(); ++e)
    ASSERT_LE((tets.corotated_strain(e, x) - expected).norm(), 1e-12) << "element " << e;
  double interior_max = 0;
  for (int i = 0; i < mesh.V.rows(); ++i) {
    const Eigen::Vector3d p = mesh.V.row(i);
    const bool interior = (p.array() > 1e-12).all() && (p.array() < kSize - 1e-12).all();
    if (interior) interior_max = std::max(interior_max, f.segment<3>(3 * i).norm());
  }
  EXPECT_LE(interior_max, 1e-9 * f.cwiseAbs().maxCoeff());
}

// Small strain, both rotation methods: the strain is the linear strain of the field.
TEST_P(TetraRotation, SmallAffineFieldGivesLinearStrain) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(3, 3, 3));
  CorotationalTetra tets(mesh.V, mesh.T, material(GetParam()));
  Eigen::Matrix3d G;
  G << 0.3, -0.2, 0.5, 0.1, -0.4, 0.2, 0.7, 0.05, 0.25;
  const double eps = 1e-6;
  const Eigen::VectorXd x =
      transform(flatten(mesh.V), Eigen::Matrix3d::Identity() + eps * G, Eigen::Vector3d::Zero());
  tets.update_rotations(x);
  const Eigen::Matrix3d linear = 0.5 * eps * (G + G.transpose());
  for (int e = 0; e < tets.size(); ++e)
    ASSERT_LE((tets.corotated_strain(e, x) - linear).norm(), 10 * eps * eps) << "element " << e;
}

INSTANTIATE_TEST_SUITE_P(BothMethods, TetraRotation,
                         ::testing::Values(RotationMethod::Geometric, RotationMethod::Polar),
                         [](const auto& info) {
                           return info.param == RotationMethod::Polar ? "Polar" : "Geometric";
                         });

// K0 against V B^T D B with the Voigt strain-displacement matrix, built independently.
TEST(TetraStiffness, MatchesVoigtFormula) {
  TetMesh mesh;
  mesh.V.resize(4, 3);
  mesh.V << 0, 0, 0, 0.01, 0.001, 0, 0.002, 0.012, 0.001, 0.001, 0.002, 0.009;
  mesh.T.resize(1, 4);
  mesh.T << 0, 1, 2, 3;
  const ParenchymaOptions o = material(RotationMethod::Polar);
  CorotationalTetra tets(mesh.V, mesh.T, o);

  Eigen::Matrix4d C;  // rows (1, x, y, z) of each node: inverse gives shape-function coefficients
  for (int i = 0; i < 4; ++i) C.row(i) << 1, mesh.V(i, 0), mesh.V(i, 1), mesh.V(i, 2);
  const Eigen::Matrix4d coeff = C.inverse();  // column i: N_i = c0 + c1 x + c2 y + c3 z
  Eigen::Matrix<double, 6, 12> B = Eigen::Matrix<double, 6, 12>::Zero();
  for (int i = 0; i < 4; ++i) {
    const double bx = coeff(1, i), by = coeff(2, i), bz = coeff(3, i);
    B(0, 3 * i) = bx;
    B(1, 3 * i + 1) = by;
    B(2, 3 * i + 2) = bz;
    B(3, 3 * i) = by, B(3, 3 * i + 1) = bx;
    B(4, 3 * i + 1) = bz, B(4, 3 * i + 2) = by;
    B(5, 3 * i) = bz, B(5, 3 * i + 2) = bx;
  }
  const double E = o.young_modulus, nu = o.poisson_ratio;
  Eigen::Matrix<double, 6, 6> D = Eigen::Matrix<double, 6, 6>::Zero();
  D.topLeftCorner<3, 3>().setConstant(nu);
  D.topLeftCorner<3, 3>().diagonal().setConstant(1 - nu);
  D.bottomRightCorner<3, 3>().diagonal().setConstant((1 - 2 * nu) / 2);
  D *= E / ((1 + nu) * (1 - 2 * nu));
  const double V = std::abs(C.determinant()) / 6;
  const Matrix12d expected = V * B.transpose() * D * B;
  EXPECT_LE((tets.rest_stiffness(0) - expected).norm(), 1e-12 * expected.norm());
}

// Around a rigidly rotated rest state the element is unstressed, so the dropped derivative of R
// contributes nothing and the tangent R K0 R^T must match finite differences of the force.
TEST_P(TetraRotation, TangentMatchesFiniteDifferencesAtRotatedRest) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(1, 1, 1));
  CorotationalTetra tets(mesh.V, mesh.T, material(GetParam()));
  const Eigen::VectorXd x = transform(flatten(mesh.V), some_rotation(), Eigen::Vector3d::Zero());
  const Eigen::VectorXd d = random_field(x.size(), 1e-7 * kSize, 7);
  const Eigen::VectorXd df = tet_forces(tets, x + d) - tet_forces(tets, x - d);
  tets.update_rotations(x);
  Eigen::VectorXd Kd = Eigen::VectorXd::Zero(x.size());
  Matrix12d Ke;
  for (int e = 0; e < tets.size(); ++e) {
    tets.element_tangent(e, Ke);
    Vector12d de;
    for (int k = 0; k < 4; ++k) de.segment<3>(3 * k) = d.segment<3>(3 * tets.elements()(e, k));
    const Vector12d fe = 2 * Ke * de;
    for (int k = 0; k < 4; ++k) Kd.segment<3>(3 * tets.elements()(e, k)) += fe.segment<3>(3 * k);
  }
  EXPECT_LE((df - Kd).norm(), 1e-6 * Kd.norm());
}

// The polar iteration warm-started from a guess (the element's last rotation) against the
// scaled iteration from F: the same rotation to round-off from near and far guesses, also for an
// inverted element (where the SVD decides) and from a half turn away (where it must restart).
TEST(PolarRotation, WarmStartMatchesTheScaledIterationFromAnyGuess) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  int checked = 0;
  for (double strain : {0.02, 0.2, 0.5}) {
    for (int trial = 0; trial < 20; ++trial) {
      Eigen::Matrix3d S;
      for (int i = 0; i < 9; ++i) S(i / 3, i % 3) = u(rng);
      S = (Eigen::Matrix3d::Identity() + 0.5 * strain * (S + S.transpose())).eval();
      if (S.determinant() < 0.05) continue;
      const Eigen::Matrix3d R_true = Eigen::AngleAxisd(3 * u(rng), Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized()).toRotationMatrix();
      Eigen::Matrix3d F = R_true * S;
      if (trial % 5 == 0) F.col(2) = -F.col(2) + 0.3 * F.col(0);  // inverted: det F < 0
      const Eigen::Matrix3d expected = polar_rotation(F);
      for (double angle : {1e-9, 1e-5, 1e-3, 0.3, 3.1}) {
        const Eigen::Vector3d axis = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
        Eigen::Quaterniond q(expected * Eigen::AngleAxisd(angle, axis).toRotationMatrix());
        const Eigen::Matrix3d R = polar_rotation(F, q);
        ASSERT_LE((R - expected).cwiseAbs().maxCoeff(), 1e-13) << "strain " << strain << " guess " << angle << " rad away";
        ASSERT_LE((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-14);
        ASSERT_LE((q.toRotationMatrix() - R).cwiseAbs().maxCoeff(), 1e-14);  // the guess follows
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 200);
}

// Four elements at once against the warm iteration one by one: lanes whose guesses are near
// (converged in the vectorized step), farther (continued alone), a half turn away (restarted
// from F) and inverted, mixed in every call.
TEST(PolarRotation, FourAtOnceMatchOneByOne) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-1, 1);
  const std::array<double, 7> angles = {1e-9, 1e-7, 1e-4, 0.3, 3.1, 1e-8, 5e-6};
  double worst = 0;
  int lanes_converged_at_once = 0;
  for (int call = 0; call < 60; ++call) {
    std::array<Eigen::Matrix3d, 4> F, R;
    std::array<Eigen::Quaterniond, 4> q, q_alone;
    for (int l = 0; l < 4; ++l) {
      Eigen::Matrix3d S;
      for (int i = 0; i < 9; ++i) S(i / 3, i % 3) = u(rng);
      S = (Eigen::Matrix3d::Identity() + 0.1 * (S + S.transpose())).eval();
      F[l] = Eigen::AngleAxisd(3 * u(rng), Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized()).toRotationMatrix() * S;
      if ((call + l) % 7 == 0) F[l].col(2) = -F[l].col(2) + 0.3 * F[l].col(0);  // inverted
      const double angle = angles[(call + 3 * l) % angles.size()];
      q[l] = Eigen::Quaterniond(polar_rotation(F[l]) *
                                Eigen::AngleAxisd(angle, Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized()).toRotationMatrix());
      q_alone[l] = q[l];
      if (angle < 1e-5 && (call + l) % 7 != 0) ++lanes_converged_at_once;
    }
    polar_rotations(F, {&q[0], &q[1], &q[2], &q[3]}, R);
    for (int l = 0; l < 4; ++l) {
      const Eigen::Matrix3d expected = polar_rotation(F[l], q_alone[l]);
      worst = std::max({worst, (R[l] - expected).cwiseAbs().maxCoeff(), (q[l].coeffs() - q_alone[l].coeffs()).cwiseAbs().maxCoeff()});
    }
  }
  EXPECT_LE(worst, 1e-14);  // round-off: R^T F is summed in another order than Eigen's product
  EXPECT_GT(lanes_converged_at_once, 40);
}

TEST(PolarRotation, ANonFiniteGradientGivesANonFiniteRotation) {
  // A node at NaN or infinity must not come out of an element as a finite rotation: the step's and
  // the analyses' finite checks rely on it. Mutation seen failing: polar_rotation's guard removed
  // (Eigen's SVD of such an F reads memory it never set, valgrind; a finite R, or not, depending on
  // what ran before).
  for (const double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    Eigen::Matrix3d F = Eigen::Matrix3d::Identity();
    F(1, 2) = bad;
    EXPECT_FALSE(polar_rotation(F).allFinite());
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    EXPECT_FALSE(polar_rotation(F, q).allFinite());
    std::array<Eigen::Matrix3d, 4> lanes_F, R;
    std::array<Eigen::Quaterniond, 4> lanes_q;
    for (int l = 0; l < 4; ++l) {
      lanes_F[l] = l == 2 ? F : Eigen::Matrix3d(Eigen::AngleAxisd(0.1 * l, Eigen::Vector3d::UnitZ()));
      lanes_q[l] = Eigen::Quaterniond::Identity();
    }
    polar_rotations(lanes_F, {&lanes_q[0], &lanes_q[1], &lanes_q[2], &lanes_q[3]}, R);
    for (int l = 0; l < 4; ++l) EXPECT_EQ(R[l].allFinite(), l != 2) << "lane " << l;
  }
}

// Element forces and damping products four at a time against one at a time, on a rotated,
// deformed mesh whose element count leaves a remainder.
TEST(TetraRotation, FourAtOnceGiveTheSameForces) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(3, 1, 1));
  CorotationalTetra block(mesh.V, mesh.T, material(RotationMethod::Polar));
  CorotationalTetra single(mesh.V, mesh.T, material(RotationMethod::Polar));
  ASSERT_NE(block.size() % 4, 0);
  const Eigen::VectorXd X = flatten(mesh.V);
  for (double amplitude : {0.0, 0.05}) {  // from the rest rotations, then warm from the first shape
    const Eigen::VectorXd x = transform(X + random_field(X.size(), amplitude * kSize + 0.01 * kSize, 21), some_rotation(), Eigen::Vector3d::Zero());
    for (int first = 0; first < block.size(); first += 4) {
      std::array<Vector12d, 4> f;
      const int count = std::min(4, block.size() - first);
      const double energy = block.element_forces(first, count, x, f.data());
      double energy_single = 0;
      for (int i = 0; i < count; ++i) {
        Vector12d expected;
        energy_single += single.element_force(first + i, x, expected);
        // A rotation that differs by round-off turns the whole shape, not only its strain.
        const double scale = single.rest_stiffness(first + i).norm() * kSize;
        ASSERT_LE((f[i] - expected).norm(), 1e-14 * scale) << "element " << first + i;
        ASSERT_LE((block.rotation(first + i) - single.rotation(first + i)).cwiseAbs().maxCoeff(), 1e-14);
      }
      ASSERT_NEAR(energy, energy_single, 1e-14 * energy_single);
    }
  }
  // The damping products with the rotations just computed, on a velocity field.
  const Eigen::VectorXd v = random_field(X.size(), 1.0, 22);
  for (int first = 0; first < block.size(); first += 4) {
    std::array<Vector12d, 4> out;
    const int count = std::min(4, block.size() - first);
    block.tangent_products(first, count, block.rotations(), v, out.data());
    for (int i = 0; i < count; ++i) {
      Vector12d expected;
      block.tangent_product(first + i, block.rotation(first + i), v, expected);
      ASSERT_LE((out[i] - expected).norm(), 1e-14 * expected.norm()) << "element " << first + i;
    }
  }
}

// A deformed shape spinning at a constant rate about a fixed axis: the predicted guesses are the
// next rotations exactly, and the forces from them are those of a model without history.
TEST(PolarRotation, PredictedGuessesContinueAConstantSpin) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(2, 2, 2));
  CorotationalTetra tets(mesh.V, mesh.T, material(RotationMethod::Polar));
  const Eigen::VectorXd y = flatten(mesh.V) + random_field(3 * mesh.V.rows(), 0.05 * kSize, 12);
  const Eigen::Vector3d axis = Eigen::Vector3d(0.3, -1.0, 0.4).normalized();
  const auto spun = [&](int k) { return transform(y, Eigen::AngleAxisd(0.02 * k, axis).toRotationMatrix(), Eigen::Vector3d::Zero()); };
  tets.update_rotations(spun(0));
  tets.predict_rotations(false);  // records only: the guesses stay at step 0
  for (int e = 0; e < tets.size(); ++e)
    ASSERT_LE((tets.rotation_guess(e).toRotationMatrix() - tets.rotation(e)).cwiseAbs().maxCoeff(), 1e-15);
  tets.update_rotations(spun(1));
  tets.predict_rotations(true);
  const Eigen::VectorXd x2 = spun(2);
  CorotationalTetra fresh(mesh.V, mesh.T, material(RotationMethod::Polar));
  for (int e = 0; e < tets.size(); ++e) {
    const Eigen::Matrix3d expected = polar_rotation(tets.deformation_gradient(e, x2));
    ASSERT_LE((tets.rotation_guess(e).toRotationMatrix() - expected).cwiseAbs().maxCoeff(), 1e-13) << "element " << e;
    Vector12d f, f_fresh;
    tets.element_force(e, x2, f);
    fresh.element_force(e, x2, f_fresh);
    ASSERT_LE((f - f_fresh).norm(), 1e-12 * f_fresh.norm()) << "element " << e;
  }
}

// The element force from the stress against R K0 (R^T x - X) with the rest stiffness, and the
// energy against 1/2 u^T K0 u, at a large deformation.
TEST_P(TetraRotation, ForceIsTheRestStiffnessOnTheCorotatedDisplacement) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(2, 2, 2));
  CorotationalTetra tets(mesh.V, mesh.T, material(GetParam()));
  const Eigen::VectorXd X = flatten(mesh.V);
  const Eigen::VectorXd x = transform(X + random_field(X.size(), 0.05 * kSize, 5), some_rotation(), Eigen::Vector3d::Zero());
  for (int e = 0; e < tets.size(); ++e) {
    Vector12d f;
    const double energy = tets.element_force(e, x, f);
    const Eigen::Matrix3d& R = tets.rotation(e);
    Vector12d u = Vector12d::Zero();
    const auto node = [&](const Eigen::VectorXd& y, int k) { return y.segment<3>(3 * tets.elements()(e, k)); };
    for (int k = 1; k < 4; ++k) u.segment<3>(3 * k) = R.transpose() * (node(x, k) - node(x, 0)) - (node(X, k) - node(X, 0));
    const Vector12d local = tets.rest_stiffness(e) * u;
    Vector12d expected;
    for (int k = 0; k < 4; ++k) expected.segment<3>(3 * k) = R * local.segment<3>(3 * k);
    ASSERT_LE((f - expected).norm(), 1e-12 * expected.norm()) << "element " << e;
    ASSERT_NEAR(energy, 0.5 * u.dot(local), 1e-12 * u.dot(local)) << "element " << e;
  }
}

// The matrix-free product (damping forces) against the element tangent times the vector.
TEST(TetraStiffness, TangentProductMatchesTheTangent) {
  const TetMesh mesh = make_box_mesh(Eigen::Vector3d::Constant(kSize), Eigen::Vector3i(2, 2, 2));
  CorotationalTetra tets(mesh.V, mesh.T, material(RotationMethod::Polar));
  const Eigen::VectorXd x = transform(flatten(mesh.V) + random_field(3 * mesh.V.rows(), 0.05 * kSize, 8), some_rotation(),
                                      Eigen::Vector3d::Zero());
  tets.update_rotations(x);
  const Eigen::VectorXd v = random_field(x.size(), 1.0, 9);
  for (int e = 0; e < tets.size(); ++e) {
    Matrix12d K;
    tets.element_tangent(e, K);
    Vector12d ve, out;
    for (int k = 0; k < 4; ++k) ve.segment<3>(3 * k) = v.segment<3>(3 * tets.elements()(e, k));
    tets.tangent_product(e, tets.rotation(e), v, out);
    const Vector12d expected = K * ve;
    ASSERT_LE((out - expected).norm(), 1e-12 * expected.norm()) << "element " << e;
  }
}

}  // namespace
}  // namespace liver_sim
