// Physics against references the code does not produce: large-deformation closed forms, the
// beam element against the textbook beam, and the torque of a contact. Each test names the mutation of scripts/mutate.py it was seen to kill
// (doc/validation.md#mutation-testing).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>

#include "liver_sim/corotational_beam.h"
#include "liver_sim/liver_model.h"
#include "regions.h"

namespace liver_sim {
namespace {

constexpr double kSlack = 1e-9;  // m: box regions reach this far past a face

// --- Large deformation -----------------------------------------------------------------------

// A cube stretched by 30% by suction on its top and bottom faces (follower loads, balanced, so
// that the supports carry nothing): held by its corner node at the origin, point-to-plane springs
// keeping the bottom face in its plane and the node at (W, 0, 0) on the x axis. Those supports
// allow the homogeneous stretch F = diag(a, a, c) about the corner, which the mesh represents
// exactly. The corotated linear law in its frame (R = I) gives the uniaxial stress E (c - 1) and
// the lateral strain a - 1 = -nu (c - 1); the suction acts on the current faces, of area
// a^2 W^2, so E e = P (1 - nu e)^2 with e = c - 1. A dead load would give E e = P.
// Kills MM1 (the pressure on the rest area: e = P / E = 0.40 instead of 0.30).
TEST(FollowerPressure, StretchedCubeCarriesTheSuctionOnItsCurrentFaces) {
  const double W = 0.01, E = 3500, nu = 0.45, P = 1400;
  Scene s;
  s.parenchyma.young_modulus = E;
  s.parenchyma.poisson_ratio = nu;
  s.solver.tolerance = 1e-10;
  s.fixed.push_back(box({-1, -1, -1}, {kSlack, kSlack, kSlack}));
  LoadOptions suction;
  suction.kind = LoadOptions::Kind::Pressure;
  suction.pressure = -P;
  for (const double z : {0.0, W}) {
    suction.region = box({-1, -1, z - kSlack}, {1, 1, z + kSlack});
    s.loads.push_back(suction);
  }
  s.probes.push_back({"far corner", {W, W, W}});
  LiverModel m(make_box_mesh({W, W, W}, {2, 2, 2}), s);
  std::vector<SurfaceTarget> rollers;
  for (int f = 0; f < m.boundary().rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      SurfaceTarget t;
      t.triangle = f;
      t.weights = Eigen::Vector3d::Unit(k);
      t.point = m.mesh().V.row(m.boundary()(f, k)).transpose();
      t.stiffness = 10 * E * W;
      if (t.point.z() < kSlack) t.normal = Eigen::Vector3d::UnitZ();
      if (t.point.isApprox(Eigen::Vector3d(W, 0, 0))) t.normal = Eigen::Vector3d::UnitY();
      if (!t.normal.isZero()) rollers.push_back(t);
    }
  m.set_surface_targets(rollers);
  const StepResult r = m.step();
  ASSERT_TRUE(r.converged()) << r.message;
  // The smaller root of P nu^2 e^2 - (2 P nu + E) e + P = 0.
  const double b = 2 * P * nu + E;
  const double e = (b - std::sqrt(b * b - 4 * P * P * nu * nu)) / (2 * P * nu * nu);
  const Eigen::Vector3d u = m.probe_displacement(0) / W;
  // Exact for the mesh: the only error is the solver's tolerance, 1e-10 of the forces, times
  // the small mesh's conditioning (measured: 7e-13).
  EXPECT_NEAR(u.z(), e, 1e-8 * e);
  EXPECT_NEAR(u.x(), -nu * e, 1e-8 * e);
  EXPECT_NEAR(u.y(), -nu * e, 1e-8 * e);
}

// --- The beam element ------------------------------------------------------------------------

// One beam along x, end a held, end b stretched or turned by a small amount: the forces are the
// columns of the textbook 12 x 12 Euler-Bernoulli stiffness (Przemieniecki), from the section
// computed here: axial E A / L, torsion G J / L with the polar moment J, and for a turn theta of
// end b about y or z the moments 4 E I theta / L at b and 2 E I theta / L at a with the shear
// forces 6 E I theta / L^2 that balance them. Stretch and turns of 1e-6: linear to O(1e-6),
// tolerance 1e-5 (measured: 6e-12).
// Kills B1 (J = I), B2 (the x-z plane's coupling sign), B3 (carry-over moment 4 E I / L), B4
// (the section's area).
TEST(BeamElement, StretchTwistAndEndTurnsGiveTheTextbookForces) {
  const double L = 0.01, ro = 0.002, ri = 0.0015, E = 0.62e6, nu = 0.45, stretch = 1e-6 * L, turn = 1e-6;
  BeamSection section;
  section.outer_radius = ro;
  section.wall_thickness = ro - ri;
  section.young_modulus = E;
  section.poisson_ratio = nu;
  const double A = M_PI * (ro * ro - ri * ri), I = M_PI / 4 * (std::pow(ro, 4) - std::pow(ri, 4));
  const double J = 2 * I, G = E / (2 * (1 + nu)), EI = E * I;
  Eigen::MatrixX3d X(2, 3);
  X << 0, 0, 0, L, 0, 0;
  Eigen::MatrixX2i segment(1, 2);
  segment << 0, 1;
  CorotationalBeams beam(X, segment, {section});
  // [f_a, m_a, f_b, m_b] with end b at (L + stretch, 0, 0), turned by the rotation vector w.
  const auto forces = [&](double stretch, const Eigen::Vector3d& w) {
    Eigen::VectorXd p(6);
    p << 0, 0, 0, L + stretch, 0, 0;
    beam.update_frames(p, {Eigen::Matrix3d::Identity(), rotation_exp(w)});
    Vector12d f;
    beam.element_force(0, f);
    return f;
  };
  const auto expect_forces = [](const Vector12d& f, const Vector12d& expected) {
    EXPECT_LE((f - expected).norm(), 1e-5 * expected.norm()) << f.transpose() << "\n  expected " << expected.transpose();
  };
  const double axial = E * A / L * stretch, torsion = G * J / L * turn;
  const double near = 2 * EI / L * turn, far = 4 * EI / L * turn, shear = 6 * EI / (L * L) * turn;
  Vector12d expected;
  expected << -axial, 0, 0, 0, 0, 0, axial, 0, 0, 0, 0, 0;
  expect_forces(forces(stretch, Eigen::Vector3d::Zero()), expected);
  expected << 0, 0, 0, -torsion, 0, 0, 0, 0, 0, torsion, 0, 0;
  expect_forces(forces(0, turn * Eigen::Vector3d::UnitX()), expected);
  expected << 0, shear, 0, 0, 0, near, 0, -shear, 0, 0, 0, far;
  expect_forces(forces(0, turn * Eigen::Vector3d::UnitZ()), expected);
  expected << 0, 0, -shear, 0, near, 0, 0, 0, shear, 0, far, 0;
  expect_forces(forces(0, turn * Eigen::Vector3d::UnitY()), expected);
}

// --- Contact -----------------------------------------------------------------------------------

// A frictionless shaft (r = 3 mm) lying 1 mm deep across the top of a 20 mm block that is
// mirror-symmetric about x = 10 mm, its tip 10 mm beyond the block's edge (local z turned onto
// x): the tissue's forces on it add up to a vertical force whose line of action is the plane
// x = 10 mm, so the torque about the tip is the 20 mm lever arm along x times the force. The
// contact solve's tolerances may break the symmetry slightly: 1e-6 (measured: 3e-14).
// Kills K2 (the torque's sign).
TEST(ContactTorque, ShaftAcrossABlockFeelsTheLeverArmTimesTheForce) {
  const Scene s = parse_scene(R"(
mesh: {box: {size: [0.02, 0.02, 0.02], divisions: [6, 6, 6]}}
parenchyma: {young_modulus: 3000}
fixed: [{box: {min: [-1, -1, -1], max: [1, 1, 1e-9]}}]
solver: {tolerance: 1e-8}
instruments:
  - name: shaft
    type: shaft
    radius: 0.003
    length: 0.04
    pose: {position: [-0.01, 0.01, 0.022], orientation: [0, 0.7071067811865476, 0, 0.7071067811865476]}
)",
                              ".", "shaft scene");
  LiverModel m(load_scene_mesh(s), s);
  const StepResult r = m.step();
  ASSERT_TRUE(r.converged()) << r.message;
  const InstrumentReaction& reaction = m.instrument_reaction(0);
  ASSERT_GT(reaction.force.z(), 0.0);
  const Eigen::Vector3d lever_arm(0.02, 0, 0);
  EXPECT_LE((reaction.torque - lever_arm.cross(reaction.force)).norm(), 1e-6 * lever_arm.norm() * reaction.force.norm())
      << reaction.torque.transpose();
}

}  // namespace
}  // namespace liver_sim
