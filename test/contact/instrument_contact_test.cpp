// Instruments in frictional contact: no penetration, stick and slip, equilibrium with the
// supports, Hertz indentation under mesh refinement, graspers, shafts, tubes, the skipped contact
// path, and bad input.
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
#include "contact/block_scenes.h"

namespace liver_sim {
namespace {

// A quaternion is a rotation at any scale: (0, 1e200, 0, 0) is the half turn about x (its
// norm() overflows to infinity, and normalized() made it zero: the identity). Killed by
// make_pose with normalized() (tried).
TEST(Instrument, AQuaternionOfAnyScaleIsItsRotation) {
  const Eigen::Vector3d p(0.01, 0, 0);
  const Eigen::Matrix3d half_turn = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  EXPECT_TRUE(make_pose(p, Eigen::Quaterniond(0, 1e200, 0, 0)).linear().isApprox(half_turn, 1e-12));
  EXPECT_TRUE(make_pose(p, Eigen::Quaterniond(0, 1e-100, 0, 0)).linear().isApprox(half_turn, 1e-12));
  InstrumentOptions o = probe("p", p, 0.003);
  o.orientation = Eigen::Quaterniond(0, 1e200, 0, 0);
  EXPECT_EQ(validate(o), "");
  o.orientation = Eigen::Quaterniond(0, 1e-100, 0, 0);  // below the bound: no direction to trust
  EXPECT_NE(validate(o), "");
}

// A sphere pressed 2 mm into a block clamped at its base: no node inside it beyond the stated
// tolerance, the tissue pushes it back, symmetric forces, and the probe's reaction equals the
// supports' (nothing else loads the block). Withdrawn, the block springs back.
TEST(Probe, PressedIntoBlockBalancesTheSupports) {
  const double L = 0.02, r = 0.004;
  LiverModel m(make_box_mesh({L, L, L}, {8, 8, 8}), block_scene(3000, 0.45, 0.0));
  InstrumentOptions p = probe("probe", {L / 2, L / 2, L + r - 0.002}, r);
  const int k = m.add_instrument(p);
  const StepResult res = m.step();
  ASSERT_TRUE(res.converged()) << res.message << " residual " << res.residual;
  const InstrumentReaction reaction = m.instrument_reaction(k);
  EXPECT_GT(reaction.contacts, 4);
  EXPECT_GT(reaction.force.z(), 0.0) << "the tissue pushes the probe back";
  EXPECT_LE(std::hypot(reaction.force.x(), reaction.force.y()), 1e-6 * reaction.force.z());
  EXPECT_LE(reaction.torque.norm(), 1e-6 * reaction.force.z() * r);
  for (int i = 0; i < m.mesh().V.rows(); ++i)
    ASSERT_GE((node(m, i) - p.position).norm(), r - kTolerance) << "node " << i << " inside the probe";
  const Eigen::Vector3d support = total(m.stepper().support_forces());
  EXPECT_LE((support - reaction.force).norm(), 1e-6 * reaction.force.norm()) << support.transpose();

  p.position.z() -= 0.001;
  m.update_instrument(k, p);
  ASSERT_TRUE(m.step().converged());
  EXPECT_GT(m.instrument_reaction(k).force.z(), reaction.force.z()) << "deeper, harder";

  p.enabled = false;
  m.update_instrument(k, p);
  const StepResult back = m.step();
  ASSERT_TRUE(back.converged()) << back.message;
  EXPECT_LE(m.displacement().cwiseAbs().maxCoeff(), 1e-9 * L);
  EXPECT_EQ(m.instrument_reaction(k).contacts, 0);
}

// Pressed with friction 0.4 and dragged along x along a scene trajectory (static pseudo-time,
// dt = 1 per step): a short drag sticks (the node under the probe moves with it and the
// tangential force of its contact stays inside the cone); a long one slides (every contact's
// force sits on the cone, |Ft| = mu Fn, and the node lags behind the probe).
TEST(Probe, DragSticksBelowCoulombAndSlidesAbove) {
  const double L = 0.02, r = 0.005, mu = 0.4;
  Scene s = block_scene(3000, 0.3, mu);
  s.solver.dt = 1.0;
  InstrumentOptions p = probe("probe", Eigen::Vector3d::Zero(), r);
  const Eigen::Vector3d pressed(L / 2, L / 2, L + r - 0.0015);
  for (const auto& [t, dx] : std::vector<std::pair<double, double>>{{1, 0}, {2, 0.00002}, {3, 0.004}}) {
    InstrumentOptions::Keyframe f;
    f.t = t;
    f.position = pressed + Eigen::Vector3d(dx, 0, 0);
    p.trajectory.push_back(f);
  }
  s.instruments.push_back(p);
  LiverModel m(make_box_mesh({L, L, L}, {10, 10, 10}), s);
  int top = -1;  // the node under the probe's centre
  for (int i = 0; i < m.mesh().V.rows(); ++i)
    if ((m.mesh().V.row(i).transpose() - Eigen::Vector3d(L / 2, L / 2, L)).norm() < 1e-9) top = i;
  ASSERT_GE(top, 0);

  // Per contact: the force at its surface point, split along the probe's normal there.
  auto split = [&](const InstrumentContact::Contact& c) {
    const Eigen::Vector3d n = (c.point.at(m.positions()) - m.contact().pose(0).translation()).normalized();
    const Eigen::Vector3d force = c.frame * c.lambda;
    return std::make_pair(force.dot(n), (force - force.dot(n) * n).norm());
  };
  // The contact at the node under the probe's centre.
  auto at_top = [&]() {
    for (const InstrumentContact::Contact& c : m.contact().contacts())
      if (c.point.count == 1 && c.point.nodes[0] == top) return c;
    ADD_FAILURE() << "no contact at the top node";
    InstrumentContact::Contact none{};  // no force, so that the checks below fail too
    none.frame.setIdentity();
    none.lambda.setZero();
    return none;
  };
  ASSERT_TRUE(m.step().converged());
  const Eigen::Vector3d before = node(m, top);
  const StepResult small = m.step();
  ASSERT_TRUE(small.converged()) << small.message;
  const Eigen::Vector3d F = m.instrument_reaction(0).force;
  EXPECT_NEAR(node(m, top).x() - before.x(), 0.00002, kTolerance) << "sticks: moves with the probe";
  EXPECT_GT(std::abs(F.x()), 0.0);
  const auto [fn, ft] = split(at_top());
  EXPECT_LT(ft, 0.9 * mu * fn) << "inside the cone";

  const Eigen::Vector3d before_drag = node(m, top);
  const StepResult large = m.step();
  ASSERT_TRUE(large.converged()) << large.message;
  int sliding = 0;
  for (const InstrumentContact::Contact& c : m.contact().contacts()) {
    const auto [n_i, t_i] = split(c);
    if (n_i == 0) continue;
    EXPECT_NEAR(t_i, mu * n_i, 1e-6 * mu * n_i) << "contact at node " << c.point.nodes[0] << " slides: on the cone";
    ++sliding;
  }
  EXPECT_EQ(sliding, m.instrument_reaction(0).contacts);
  EXPECT_LT(m.instrument_reaction(0).force.x(), 0.0) << "the tissue drags the probe back";
  EXPECT_LT(node(m, top).x() - before_drag.x(), 0.5 * 0.004) << "the surface lags behind";
}

// A closed grasper holds the surface nodes within its radius and carries them with it; opened,
// it lets the block spring back.
TEST(Grasper, HoldsWhileClosedAndReleasesWhenOpened) {
  const double L = 0.02;
  Scene s = block_scene(3000, 0.45, 0.0);
  s.solver.dt = 1.0;
  InstrumentOptions g = grasper(0.003);
  const Eigen::Vector3d at(L / 2, L / 2, L);
  for (const auto& [t, lift, closed] : std::vector<std::tuple<double, double, bool>>{{1, 0, true}, {2, 0.002, true}, {3, 0.002, false}}) {
    InstrumentOptions::Keyframe f;
    f.t = t;
    f.position = at + Eigen::Vector3d(0, 0, lift);
    f.closed = closed;
    g.trajectory.push_back(f);
  }
  s.instruments.push_back(g);
  LiverModel m(make_box_mesh({L, L, L}, {8, 8, 8}), s);
  ASSERT_TRUE(m.step().converged());
  const Eigen::VectorXd grasped = m.positions();
  const StepResult lifted = m.step();
  ASSERT_TRUE(lifted.converged()) << lifted.message;
  const InstrumentReaction& held = m.instrument_reaction(0);
  EXPECT_GE(held.contacts, 5);  // the node under it and its four neighbours 2.5 mm away
  EXPECT_LT(held.force.z(), 0.0) << "the tissue pulls the grasper down";
  int moved = 0;
  for (int i = 0; i < m.mesh().V.rows(); ++i) {
    const Eigen::Vector3d d = node(m, i) - grasped.segment<3>(3 * i);
    if (m.mesh().V(i, 2) == L && (grasped.segment<3>(3 * i) - at).norm() <= g.radius) {  // surface nodes
      EXPECT_NEAR(d.z(), 0.002, kTolerance) << "held node " << i;
      ++moved;
    }
  }
  EXPECT_EQ(moved, held.contacts);
  ASSERT_TRUE(m.step().converged());
  EXPECT_LE(m.displacement().cwiseAbs().maxCoeff(), 1e-9 * L) << "released";
  EXPECT_EQ(m.instrument_reaction(0).contacts, 0);
}

// A shaft lying across the top face presses a groove: no penetration, pushed up, and the
// forces of the tissue on it balance the supports.
// A grasper that reaches no free node holds the nearest surface point, as a contact would: one
// the supports carry half or more is theirs. Beside the fixed bottom edge of a coarse block it
// holds nothing (lifting it would tear the few free nodes off the support: 77 N for 0.5 mm);
// 8 mm up the same face it holds a point and lifts it. Killed by the fallback taking any point
// with a free node (tried: it holds a point 98% on the support).
TEST(Grasper, LeavesPointsTheSupportsCarryToThem) {
  const double L = 0.02;
  for (const double z : {2e-4, 8e-3}) {
    Scene s = block_scene(3000, 0.45, 0.0);
    s.solver.dt = 1.0;
    InstrumentOptions g = grasper(0.003);
    for (int k = 0; k < 2; ++k) {  // closed beside the face x = 0, then lifted 0.5 mm
      InstrumentOptions::Keyframe f;
      f.t = 1 + k;
      f.position = Eigen::Vector3d(-0.2e-3, L / 2, z + k * 0.5e-3);
      f.closed = true;
      g.trajectory.push_back(f);
    }
    g.position = g.trajectory[0].position;
    s.instruments.push_back(g);
    LiverModel m(make_box_mesh({L, L, L}, {2, 2, 2}), s);  // nodes 10 mm apart
    ASSERT_TRUE(m.step().converged());
    const bool supported = z < 1e-3;
    EXPECT_EQ(m.contact().contacts().size(), supported ? 0u : 1u) << "z = " << z;
    const StepResult lift = m.step();
    EXPECT_TRUE(lift.converged()) << lift.message;
    if (supported)
      EXPECT_EQ(m.instrument_reaction(0).force.norm(), 0.0);
    else
      EXPECT_LT(m.instrument_reaction(0).force.z(), 0.0);  // the tissue holds the lifted jaws back
  }
}

TEST(Shaft, PressesAGrooveWithoutPenetration) {
  const double L = 0.02, r = 0.003;
  LiverModel m(make_box_mesh({L, L, L}, {8, 8, 8}), block_scene(3000, 0.45, 0.2));
  InstrumentOptions o;
  o.name = "shaft";
  o.type = InstrumentOptions::Type::Shaft;
  o.radius = r;
  o.length = 0.04;
  // Axis along +x, from x = -10 mm: the orientation turns local z onto x.
  o.orientation = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitX());
  o.position = Eigen::Vector3d(-0.01, L / 2, L + r - 0.001);
  const int k = m.add_instrument(o);
  const StepResult res = m.step();
  ASSERT_TRUE(res.converged()) << res.message;
  const InstrumentReaction& reaction = m.instrument_reaction(k);
  EXPECT_GE(reaction.contacts, 9) << "a row of nodes along the groove";
  EXPECT_GT(reaction.force.z(), 0.0);
  for (int i = 0; i < m.mesh().V.rows(); ++i) {
    const Eigen::Vector3d x = node(m, i);
    EXPECT_GE(std::hypot(x.y() - L / 2, x.z() - o.position.z()), r - kTolerance) << "node " << i;
  }
  EXPECT_LE((total(m.stepper().support_forces()) - reaction.force).norm(), 1e-6 * reaction.force.norm());
}

// A shaft turned about its tip into the block, in one step, comes to the equilibrium the same
// turn reaches in 20 small steps (frictionless: the path does not matter). Its far end travels
// 2.4 mm and its tip not at all: the step must stage the turn by the far end's travel. Killed
// by the stages counted by the tip's travel alone (tried: the one-step turn does not converge).
TEST(Shaft, ATurnIsStagedByItsFarEnd) {
  const double L = 0.02, r = 0.001, length = 0.03, theta = std::asin(2.0 / 25.0);
  const Eigen::Quaterniond along_x = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitX());
  InstrumentOptions o;
  o.name = "shaft";
  o.type = InstrumentOptions::Type::Shaft;
  o.radius = r;
  o.length = length;
  InstrumentOptions::Keyframe above, turned;
  above.t = 1;
  above.position = Eigen::Vector3d(-0.005, L / 2, L + r + 0.5e-3);  // 0.5 mm above the top face
  above.orientation = along_x;
  turned.t = 2;
  turned.position = above.position;
  turned.orientation = Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitY()) * along_x;  // the far end dips
  o.trajectory = {above, turned};
  o.position = above.position;
  o.orientation = above.orientation;
  auto settle = [&](double dt) {
    Scene s = block_scene(3000, 0.45, 0.0);
    s.solver.dt = dt;
    s.instruments.push_back(o);
    auto m = std::make_unique<LiverModel>(make_box_mesh({L, L, L}, {8, 8, 8}), s);
    while (m->time() < 2 - 1e-9) {
      const StepResult res = m->step();
      EXPECT_TRUE(res.converged()) << "dt " << dt << " at t = " << m->time() << ": " << res.message;
    }
    return m;
  };
  const auto one = settle(1.0), small = settle(0.05);
  EXPECT_GT(one->instrument_reaction(0).force.z(), 0.0);
  EXPECT_LT((one->positions() - small->positions()).cwiseAbs().maxCoeff(), 1e-7);
}

// The aspiration tube in frictional contact at its rim: the capsule reduces the lift by a
// factor near 2 (the reference test's finding); the tissue pulls the tube down onto itself;
// supports, rim and suction balance.
TEST(Tube, AspirationBalancesAndTheCapsuleHalvesTheLift) {
  const Scene scene = load_scene(std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/aspiration_tube.yaml");
  double lift[2];
  for (int capsule = 0; capsule < 2; ++capsule) {
    Scene s = scene;
    s.capsule.enabled = capsule == 1;
    LiverModel m(load_scene_mesh(s), s);
    const StepResult r = m.step();
    ASSERT_TRUE(r.converged()) << r.message;
    lift[capsule] = m.probe_displacement(0).z();
    const InstrumentReaction& tube = m.instrument_reaction(0);
    EXPECT_GT(tube.contacts, 0);
    EXPECT_GT(tube.force.z(), 0.0) << "the rim holds the tissue down: the tissue pushes the tube up";
    Eigen::VectorXd suction;
    m.mechanics().external_forces(m.positions(), suction);
    const Eigen::Vector3d sum = total(m.stepper().support_forces()) + total(m.contact().forces(m.positions())) + total(suction);
    EXPECT_LE(sum.norm(), 1e-6 * tube.force.norm()) << sum.transpose();
    for (int i = 0; i < m.mesh().V.rows(); ++i)
      ASSERT_GE(surface_distance(m.instrument(0), m.contact().pose(0), node(m, i)).distance, -kTolerance) << i;
  }
  EXPECT_GT(lift[1], 0.0);
  EXPECT_GE(lift[0] / lift[1], 1.5);
  EXPECT_LE(lift[0] / lift[1], 2.5);
}

// A 5 mm rod (2.5 mm radius, hemispherical tip) pressed 4 mm into the sagged right lobe of the
// liver phantom, whose surface triangles are ~8.5 mm across, at points between nodes: the tip
// pushes the surface in, the tissue pushes the rod back, and no part of the deformed surface
// lies inside the rod deeper than 10% of the press. The surface is checked on a grid of 30 x 30
// points per triangle, finer than the contact's own samples (half the radius apart). Checked to
// fail with the contacts at the nodes only (sample spacing infinite): at two of the three spots
// the rod then touches no node, feels no force, and the surface passes 2.5 mm into it.
TEST(SurfaceContact, ThinRodPressedBetweenNodesKeepsTheSurfaceOut) {
  Scene s = load_scene(std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/liver_phantom.yaml");
  LiverModel equilibrium(load_scene_mesh(s), s);
  ASSERT_TRUE(equilibrium.step().converged());
  const Eigen::VectorXd sagged = equilibrium.positions();
  const double r = 0.0025, press = 0.004;
  const Eigen::MatrixX3i& boundary = equilibrium.boundary();
  auto corner = [&](int t, int k) { return Eigen::Vector3d(sagged.segment<3>(3 * boundary(t, k))); };
  // Spots: the centroids of the upward-facing triangles nearest to three points of the right lobe.
  for (const Eigen::Vector2d& spot : {Eigen::Vector2d(-0.046, -0.016), Eigen::Vector2d(-0.07, 0.01), Eigen::Vector2d(-0.03, -0.04)}) {
    int best = -1;
    double best_distance = 1e9;
    for (int t = 0; t < boundary.rows(); ++t) {
      const Eigen::Vector3d n = (corner(t, 1) - corner(t, 0)).cross(corner(t, 2) - corner(t, 0)).normalized();
      const Eigen::Vector3d c = (corner(t, 0) + corner(t, 1) + corner(t, 2)) / 3;
      const double d = (c.head<2>() - spot).norm();
      if (n.z() > 0.8 && d < best_distance) best_distance = d, best = t;
    }
    ASSERT_GE(best, 0);
    const Eigen::Vector3d surface = (corner(best, 0) + corner(best, 1) + corner(best, 2)) / 3;
    // The node's path: modified Newton on a reused factor, the contact forces in the same solve.
    Scene pressed = s;
    pressed.solver.strategy = SolverOptions::Strategy::ModifiedNewton;
    pressed.solver.max_iterations = 300;
    pressed.solver.tolerance = 1e-6;  // the geometry checked below is settled long before 1e-8
    LiverModel m(load_scene_mesh(pressed), pressed);
    m.set_positions(sagged);
    InstrumentOptions rod;
    rod.name = "rod";
    rod.type = InstrumentOptions::Type::Shaft;
    rod.radius = r;
    rod.length = 0.1;
    rod.position = surface + Eigen::Vector3d(0, 0, r - press);
    m.add_instrument(rod);
    const StepResult res = m.step();
    ASSERT_TRUE(res.converged()) << res.message;
    EXPECT_GT(m.instrument_reaction(0).force.z(), 0.0) << "the tissue pushes the rod back";
    double deepest = 0;
    for (int t = 0; t < boundary.rows(); ++t)
      for (int i = 0; i <= 30; ++i)
        for (int j = 0; i + j <= 30; ++j) {
          const Eigen::Vector3d w(30 - i - j, i, j);
          Eigen::Vector3d p = Eigen::Vector3d::Zero();
          for (int k = 0; k < 3; ++k) p += w[k] / 30 * m.positions().segment<3>(3 * boundary(t, k));
          deepest = std::min(deepest, surface_distance(rod, m.contact().pose(0), p).distance);
        }
    EXPECT_GE(deepest, -0.1 * press) << "the surface passes into the rod at (" << spot.transpose() << ")";
  }
}

// Hertz: a rigid sphere (R = 10 mm) pressed delta = 0.2 mm (contact radius a = 1.41 mm) into a
// large block (120 x 120 x 60 mm, nu = 0.3, frictionless), the meshes graded towards the contact
// (sinh mapping; centre spacing 0.75, 0.5, 0.375 mm). F = 4/3 E* R^1/2 delta^3/2.
// Measured: 19.9%, 12.4%, 6.8% above Hertz, and 4.95% on a 40-division mesh (43 s, not run
// here); extrapolated from the last three, ~3%, of which the block's finite depth accounts for
// about 2% (bonded layer, a/D = 0.024). Hence: the error must fall with each refinement and be
// below 8% on the finest mesh run here.
TEST(Hertz, SmallIndentationApproachesTheoryUnderRefinement) {
  const double E = 3000, nu = 0.3, R = 0.01, delta = 0.0002, H = 0.06, D = 0.06, beta = 4.5;
  const double hertz = 4.0 / 3.0 * E / (1 - nu * nu) * std::sqrt(R) * std::pow(delta, 1.5);
  auto grade = [beta](double u) { return std::sinh(beta * u) / std::sinh(beta); };  // u in [-1, 1]
  std::vector<double> error;
  for (int n : {16, 24, 32}) {
    TetMesh mesh = make_box_mesh({2 * H, 2 * H, D}, {n, n, n / 2});
    for (int i = 0; i < mesh.V.rows(); ++i) {
      mesh.V(i, 0) = H * grade(mesh.V(i, 0) / H - 1);
      mesh.V(i, 1) = H * grade(mesh.V(i, 1) / H - 1);
      mesh.V(i, 2) = -D * grade(1 - mesh.V(i, 2) / D);  // top at z = 0
    }
    Scene s = block_scene(E, nu, 0.0);
    s.fixed = {box({-1, -1, -1}, {1, 1, -D + 1e-9})};
    LiverModel m(mesh, s);
    m.add_instrument(probe("sphere", {0, 0, R - delta}, R));
    const StepResult r = m.step();
    ASSERT_TRUE(r.converged()) << "n = " << n << ": " << r.message;
    const double F = m.instrument_reaction(0).force.z();
    error.push_back((F - hertz) / hertz);
    std::cout << "n = " << n << ": " << m.instrument_reaction(0).contacts << " contacts, F = " << F
              << " N, Hertz " << hertz << " N, error " << 100 * error.back() << "%\n";
  }
  EXPECT_GT(error[2], 0.0) << "linear tetrahedra are stiff, never soft";
  EXPECT_LT(error[1], error[0]);
  EXPECT_LT(error[2], error[1]);
  EXPECT_LT(error[2], 0.08);
}

// Nothing within the alarm distance: no contact problem is solved and no compliance column is
// computed, step after step. Brought into contact, both counters move.
TEST(Contact, PathSkippedWhenNoInstrumentTouches) {
  const double L = 0.02;
  Scene s = block_scene(3000, 0.45, 0.3);
  s.loads.push_back(LoadOptions::gravity({0, 0, -9.81}));
  s.solver.mode = SolverOptions::Mode::Dynamic;
  s.solver.dt = 0.01;
  LiverModel m(make_box_mesh({L, L, L}, {6, 6, 6}), s);
  InstrumentOptions p = probe("probe", {L / 2, L / 2, L + 0.01}, 0.003);  // 7 mm above
  const int k = m.add_instrument(p);
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(m.step().converged());
  EXPECT_EQ(m.contact().solves(), 0);
  EXPECT_EQ(m.contact().compliance_columns(), 0);
  p.position.z() = L + 0.003 - 0.002;  // 2 mm below the rest surface, ~1.3 mm below the sagged one
  m.update_instrument(k, p);
  ASSERT_TRUE(m.step().converged());
  EXPECT_GT(m.contact().solves(), 0);
  EXPECT_GT(m.contact().compliance_columns(), 0);
}

// Bad input: a clear error for zero or negative sizes, NaN poses, negative friction; an
// instrument started deep inside the tissue gives finite positions, converged or rolled back.
TEST(Contact, BadInputIsRefusedOrStable) {
  const double L = 0.02;
  LiverModel m(make_box_mesh({L, L, L}, {6, 6, 6}), block_scene(3000, 0.45, 0.3));
  EXPECT_THROW(m.add_instrument(probe("zero", {0, 0, 0}, 0.0)), std::invalid_argument);
  EXPECT_THROW(m.add_instrument(probe("negative", {0, 0, 0}, -1e-3)), std::invalid_argument);
  EXPECT_THROW(m.add_instrument(probe("nan", {std::nan(""), 0, 0}, 1e-3)), std::invalid_argument);
  InstrumentOptions tube;
  tube.name = "tube";
  tube.type = InstrumentOptions::Type::Tube;
  tube.inner_radius = 0.006;
  tube.outer_radius = 0.005;
  EXPECT_THROW(m.add_instrument(tube), std::invalid_argument);
  const int k = m.add_instrument(probe("probe", {L / 2, L / 2, L + 0.01}, 0.003));
  InstrumentOptions bad = m.instrument(k);
  bad.orientation.coeffs() << 0, 0, 0, std::nan("");
  EXPECT_THROW(m.update_instrument(k, bad), std::invalid_argument);
  EXPECT_TRUE(m.instrument(k).orientation.coeffs().allFinite()) << "the last good options are kept";
  Scene s = block_scene(3000, 0.45, -0.1);
  EXPECT_THROW(LiverModel(make_box_mesh({L, L, L}, {2, 2, 2}), s), std::invalid_argument);

  InstrumentOptions deep = m.instrument(k);
  deep.position = Eigen::Vector3d(L / 2, L / 2, L - 0.006);  // centre 6 mm under the surface
  m.update_instrument(k, deep);
  const StepResult r = m.step();
  EXPECT_TRUE(m.positions().allFinite());
  if (r.status == StepResult::Status::Diverged) {
    EXPECT_EQ(m.max_displacement(), 0.0) << "rolled back";
  }
}

}  // namespace
}  // namespace liver_sim
