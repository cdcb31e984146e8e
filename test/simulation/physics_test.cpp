// Physics against references the code does not produce: large-deformation closed forms, the
// beam element against the textbook beam, vibration against the closed-form eigenfrequency and
// backward Euler's known dissipation, each rollback detector triggered by an honest input, and
// the torque of a contact. Each test names the mutation of scripts/mutate.py it was seen to kill
// (doc/validation.md#mutation-testing).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <complex>
#include <cstdio>
#include <limits>

#include "liver_sim/model/corotational_beam.h"
#include "liver_sim/simulation/liver_model.h"
#include "regions.h"
#include "simulation/scenes.h"

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

// --- Vibration ---------------------------------------------------------------------------------

// A column fixed at its base and free at its top, nu = 0 (no lateral stress: a rod), released at
// rest from its first mode shape u_z = a sin(pi z / 2L), a = 1e-4 L (strains of 1e-4: linear)
// unless said otherwise. Its first eigenfrequency is omega = pi c / 2L with c = sqrt(E / rho).
struct Rod {
  static constexpr double L = 0.08, width = 0.01, E = 3000, rho = 1000;
  static double omega() { return M_PI / (2 * L) * std::sqrt(E / rho); }
  // 0.05 rad of the first mode per step: 126 steps a period.
  static double dt() { return 0.05 / omega(); }
};

// The rod's scene, dynamic, with the given damping and capsule.
Scene rod_scene(double rayleigh_mass, double rayleigh_stiffness, bool capsule) {
  Scene s;
  s.parenchyma.young_modulus = Rod::E;
  s.parenchyma.poisson_ratio = 0.0;
  s.parenchyma.density = Rod::rho;
  s.capsule.enabled = capsule;
  s.solver.mode = SolverOptions::Mode::Dynamic;
  s.solver.dt = Rod::dt();
  s.solver.tolerance = 1e-10;
  s.solver.rayleigh_mass = rayleigh_mass;
  s.solver.rayleigh_stiffness = rayleigh_stiffness;
  s.fixed.push_back(box({-1, -1, -1}, {1, 1, kSlack}));
  s.probes.push_back({"tip", {Rod::width / 2, Rod::width / 2, Rod::L}});
  return s;
}

// n x n x 8n hexahedra.
TetMesh rod_mesh(int n) { return make_box_mesh({Rod::width, Rod::width, Rod::L}, {n, n, 8 * n}); }

// At rest in the first mode shape, amplitude `a` (m).
void release(LiverModel& m, double a) {
  Eigen::VectorXd x = m.positions();
  for (int i = 2; i < x.size(); i += 3) x[i] += a * std::sin(M_PI * x[i] / (2 * Rod::L));
  m.set_positions(x);
}

// Backward Euler maps each mode's continuous eigenvalue s (s^2 + c s + omega^2 = 0 for a
// damping rate c) to the factor z = 1 / (1 - s dt) per step. The dominant z of the tip's motion
// from step `first` on (Prony: u_k+1 = p u_k + q u_k-1 by least squares, z a root of
// z^2 - p z - q), and s = (1 - 1/z) / dt.
std::complex<double> continuous_eigenvalue(const std::vector<double>& u, double dt, int first) {
  const int n = static_cast<int>(u.size()) - first - 2;
  Eigen::MatrixXd A(n, 2);
  Eigen::VectorXd b(n);
  for (int k = 0; k < n; ++k) {
    A.row(k) << u[first + k + 1], u[first + k];
    b[k] = u[first + k + 2];
  }
  const Eigen::Vector2d pq = A.colPivHouseholderQr().solve(b);
  const std::complex<double> z(pq[0] / 2, std::sqrt(std::max(0.0, -pq[1] - pq[0] * pq[0] / 4)));
  return (1.0 - 1.0 / z) / dt;
}

// The tip's displacement at the start and after each of `steps` steps.
std::vector<double> tip_motion(LiverModel& m, int steps) {
  std::vector<double> u = {m.probe_displacement(0).z()};
  for (int k = 0; k < steps; ++k) {
    const StepResult r = m.step();
    EXPECT_TRUE(r.converged()) << "step " << k << ": " << r.message;
    u.push_back(m.probe_displacement(0).z());
  }
  return u;
}

// The frequency on 8 and 16 layers against the closed form. Lumped masses lower it by O(h^2)
// (for the 1D chain of lumped masses exactly omega_h = (2c/h) sin(pi h / 4L), 0.16% low on 8
// layers; the tetrahedra measure 0.20% and 0.050%): the error must fall fourfold per halving
// of h, from below, and the Richardson extrapolation (4 omega_16 - omega_8) / 3 must meet the
// closed form within 2e-5 (what remains: the O(h^4) term, ~4e-6, and the fit, ~1e-6; measured
// 1.5e-6).
// Backward Euler's own frequency error is exact and removed: omega = |s| above.
// Kills NS1 (inertia with half the mass: sqrt 2 too high) and MM3 (lumped mass halved).
TEST(Vibration, RodFrequencyConvergesToTheClosedFormUnderRefinement) {
  double omega[2];
  for (int n = 1; n <= 2; ++n) {
    LiverModel m(rod_mesh(n), rod_scene(0, 0, false));
    release(m, 1e-4 * Rod::L);
    omega[n - 1] = std::abs(continuous_eigenvalue(tip_motion(m, 400), Rod::dt(), 50));
  }
  const double coarse = omega[0] / Rod::omega() - 1, fine = omega[1] / Rod::omega() - 1;
  EXPECT_LT(coarse, 0.0) << "lumped masses lower the frequency";
  EXPECT_LT(fine, 0.0);
  EXPECT_NEAR(coarse / fine, 4.0, 0.5) << "second order: " << coarse << ", " << fine;
  EXPECT_NEAR((4 * omega[1] - omega[0]) / 3, Rod::omega(), 2e-5 * Rod::omega());
}

// Undamped, backward Euler takes a fraction of each mode's energy per step that depends only on
// omega dt: the map of (omega x, v) is a rotation scaled by (1 + omega^2 dt^2)^-1/2, so the
// energy falls by the factor 1 / (1 + omega^2 dt^2) per step, for every state. The kinetic plus
// strain energy over 300 steps, once the higher modes have died out (they decay faster), against
// that factor with the rod's frequency as measured: within 1e-5 of the fall to 47% (the higher
// modes' remaining share of the energy and the fit, ~1e-6; measured 2e-7). The fitted
// eigenvalue itself has no real part beyond 1e-5 of |s| (measured 7e-7).
// Kills NS4 (inertia against the velocity of the step before), NS5 (velocity update halved).
TEST(Vibration, BackwardEulerDissipatesExactlyItsClosedFormShare) {
  LiverModel m(rod_mesh(1), rod_scene(0, 0, false));
  release(m, 1e-4 * Rod::L);
  const Eigen::VectorXd& mass = m.mechanics().mass();
  std::vector<double> u = {m.probe_displacement(0).z()}, energy;
  for (int k = 0; k < 400; ++k) {
    const Eigen::VectorXd before = m.positions();
    ASSERT_TRUE(m.step().converged()) << "step " << k;
    const Eigen::VectorXd v = (m.positions() - before) / Rod::dt();
    energy.push_back(m.mechanics().elastic_energy(m.positions()) + 0.5 * v.dot(mass.cwiseProduct(v)));
    u.push_back(m.probe_displacement(0).z());
  }
  const std::complex<double> s = continuous_eigenvalue(u, Rod::dt(), 50);
  const double omega_dt = std::abs(s) * Rod::dt();
  EXPECT_NEAR(energy[399] / energy[99], std::pow(1 + omega_dt * omega_dt, -300), 1e-5);
  EXPECT_LE(std::abs(s.real()), 1e-5 * std::abs(s)) << "no dissipation beyond backward Euler's";
}

// Rayleigh damping D = a M + b K damps each mode at the rate c = a + b omega^2: the continuous
// eigenvalue has Re s = -c/2 and |s| = omega. Measured on the rod with the capsule (its
// membranes on the sides add stiffness, and b K must include theirs): Re s = -(a + b |s|^2) / 2
// within 1e-4 of the rate (the fit's error; measured 2e-6).
// Kills NS2 (a with the wrong sign), NS3 (half of b K), MM7 (the capsule left out of b K).
TEST(Vibration, RayleighDampingDecaysEachModeAtItsRate) {
  const double a = 2.0, b = 1e-3;  // 1/s, s
  LiverModel m(rod_mesh(1), rod_scene(a, b, true));
  release(m, 1e-4 * Rod::L);
  const std::complex<double> s = continuous_eigenvalue(tip_motion(m, 300), Rod::dt(), 50);
  const double c = a + b * std::norm(s);
  EXPECT_GT(std::abs(s), 1.5 * Rod::omega()) << "the capsule stiffens the rod";
  EXPECT_NEAR(s.real(), -c / 2, 1e-4 * c);
}

// Ten steps of the linear rod released from a tiny stretch, to the tolerance 1e-9: each must
// converge within `iterations`.
void expect_linear_steps_within(SolverOptions::Strategy strategy, bool line_search, int iterations) {
  Scene s = rod_scene(2.0, 1e-3, false);
  s.solver.strategy = strategy;
  s.solver.line_search = line_search;
  s.solver.tolerance = 1e-9;
  LiverModel m(rod_mesh(1), s);
  release(m, 1e-7 * Rod::L);
  for (int k = 0; k < 10; ++k) {
    const StepResult r = m.step();
    ASSERT_TRUE(r.converged()) << r.message;
    EXPECT_LE(r.iterations, iterations) << "step " << k;
  }
}

// For a linear problem (the rod at strains of 1e-7) the Newton matrix (1 + b/dt) K +
// (1/dt^2 + a/dt) M is the exact Jacobian of the backward-Euler residual, so full Newton solves
// every step in one iteration to the tolerance 1e-9; a wrong matrix converges linearly and
// needs many.
// Kills MM5 (half the mass in the matrix) and NS6 (its mass term over dt, not dt^2).
TEST(NewtonMatrix, OneIterationSolvesALinearDynamicStep) {
  expect_linear_steps_within(SolverOptions::Strategy::FullNewton, true, 1);
}

// Newton-Krylov's GMRES runs on the Jacobian as directional differences of the residual. For the
// linear rod those are exact, so the Newton step is exact up to GMRES's forcing term (at most
// 1e-6 of the residual): without line search to hide a wrong length, every step converges to the
// tolerance 1e-9 within two iterations. A Jacobian off by a factor overshoots or undershoots by it
// and the residual does not fall.
// Kills NS13 (the difference quotient over 2h: every Newton step twice too long).
TEST(NewtonMatrix, NewtonKrylovSolvesALinearDynamicStepInTwoIterations) {
  expect_linear_steps_within(SolverOptions::Strategy::NewtonKrylov, false, 2);
}

// --- Rollback detectors --------------------------------------------------------------------------

// Each detector, triggered by an input that honestly leads there: the step is rolled back to
// the exact state before it, every observable value to the last bit (velocities, rotations and
// their warm starts included: simulation/rollback_test.cpp covers the instruments), and says which
// detector fired.
StepResult expect_rolled_back(LiverModel& m, const std::string& reason) {
  const std::vector<double> before = m.observable_state();
  const double time = m.time();
  const StepResult r = m.step();
  EXPECT_EQ(r.status, StepResult::Status::Diverged) << r.message;
  EXPECT_EQ(r.message.rfind(reason, 0), 0u) << r.message;
  EXPECT_TRUE(same_bits(m.observable_state(), before));
  EXPECT_EQ(m.time(), time);
  return r;
}

// A load that is not a number (a corrupted pressure reading): caught at the residual, before a
// factorisation is spent on it.
// Kills NS8 (NaN passing the check: the step then fails later, at the Newton update).
TEST(Rollback, NonFiniteLoadIsCaughtAtTheResidual) {
  Scene s = aspiration_cube();
  LiverModel m(load_scene_mesh(s), s);
  ASSERT_TRUE(m.step().converged());
  m.set_load_scale(std::numeric_limits<double>::quiet_NaN());
  expect_rolled_back(m, "non-finite residual");
}

// 100 kPa of suction on 3.5 kPa tissue in one full-Newton step without line search: the
// linear step stretches the top several times its size, the follower load grows with the area
// and the residual with it, a millionfold within a few iterations. The detector fires at the
// first iterate past a millionfold: the iterate before it, where the same step capped one
// iteration earlier ends (kept, or rolled back as a stall whose message gives its merit), has a
// static residual f_ext(x) - f_int(x) on the free DOFs, computed here from the mechanical model,
// below a millionfold of the start's.
// Kills NS9 (the threshold a million times higher: the step runs on past a millionfold).
TEST(Rollback, FullNewtonStepsWithoutLineSearchBlowUp) {
  Scene s = aspiration_cube();
  s.loads[0].pressure = -1e5;
  s.solver.strategy = SolverOptions::Strategy::FullNewton;
  s.solver.line_search = false;
  LiverModel m(load_scene_mesh(s), s);
  const Eigen::VectorXd rest = m.positions();
  const StepResult r = expect_rolled_back(m, "residual blow-up");
  ASSERT_GE(r.iterations, 2);
  MechanicalModel mechanics(load_scene_mesh(s), s, load_vessel_trees(s));
  auto static_residual = [&](const Eigen::VectorXd& x) {
    Eigen::VectorXd f_int, f;
    mechanics.internal_forces(x, f_int);
    mechanics.external_forces(x, f);
    f -= f_int;
    for (int i = 0; i < f.size(); ++i)
      if (mechanics.fixed_dofs()[i]) f[i] = 0;
    return f.norm();
  };
  const double start = static_residual(rest);
  double fired = 0, start_reported = 0;
  ASSERT_EQ(std::sscanf(r.message.c_str(), "residual blow-up: %lf N against %lf N", &fired, &start_reported), 2)
      << r.message;
  EXPECT_NEAR(start_reported, start, 1e-5 * start);  // printed to 6 digits
  EXPECT_GT(fired, 1e6 * start);
  s.solver.max_iterations = r.iterations - 1;
  LiverModel capped(load_scene_mesh(s), s);
  const StepResult before = capped.step();
  double previous = 0;
  if (before.status == StepResult::Status::Diverged)
    ASSERT_EQ(std::sscanf(before.message.c_str(), "stalled: residual %lf N after", &previous), 1) << before.message;
  else
    previous = static_residual(capped.positions());
  EXPECT_LT(previous, 1e6 * start);
}

// The tangent R K0 R^T (with membranes, beams, springs and mass) is positive semi-definite by
// construction, whatever the rotations, so an inverted start does not make it indefinite; it is
// singular only where nothing holds the tissue. A mesh node that no tetrahedron uses (the mesh
// readers drop such nodes; a mesh built in code can keep one) has no stiffness at all.
// Kills NS12 (the factorisation's refusal ignored: the step runs on a broken factor).
TEST(Rollback, UnsupportedNodeMakesTheTangentSingular) {
  TetMesh mesh = make_box_mesh({0.01, 0.01, 0.01}, {2, 2, 2});
  mesh.V.conservativeResize(mesh.V.rows() + 1, 3);
  mesh.V.bottomRows<1>() << 0.02, 0.02, 0.02;
  Scene s;
  s.fixed.push_back(box({-1, -1, -1}, {1, 1, kSlack}));
  s.loads.push_back(LoadOptions::gravity({0, 0, -9.81}));
  LiverModel m(mesh, s);
  expect_rolled_back(m, "tangent matrix is not positive definite");
}

// Real-time frames (one modified-Newton iteration, no line search) started from the
// constant-acceleration prediction, under a suction that jumps between 20% and 100% every frame:
// the prediction extrapolates the zig-zag, one iteration does not bring it back, and the third
// frame ends with 3.6 times the energy it started with while the loads did far less work.
// Backward Euler cannot gain energy: the frame is rolled back.
// Kills NS11 (the energy threshold ten times higher).
TEST(Rollback, CappedFramesThatGainEnergyAreRolledBack) {
  Scene s = aspiration_cube();
  s.solver.mode = SolverOptions::Mode::Dynamic;
  s.solver.dt = 0.01;
  s.solver.strategy = SolverOptions::Strategy::ModifiedNewton;
  s.solver.predictor = SolverOptions::Predictor::ConstantAcceleration;
  s.solver.max_iterations = 1;
  s.solver.tolerance = 1e-300;
  s.solver.line_search = false;
  LiverModel m(load_scene_mesh(s), s);
  for (int frame = 0; frame < 2; ++frame) {
    m.set_load_scale(frame % 2 ? 1.0 : 0.2);
    const StepResult r = m.step();
    ASSERT_NE(r.status, StepResult::Status::Diverged) << "frame " << frame << ": " << r.message;
  }
  m.set_load_scale(0.2);
  expect_rolled_back(m, "energy growth");
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
