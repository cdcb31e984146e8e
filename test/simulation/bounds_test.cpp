// Every field that sizes work or lies beyond tissue has a bound; refusals change nothing.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <new>
#include <stdexcept>

#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/geometry/mesh.h"
#include "liver_sim/registration/registration.h"
#include "liver_sim/simulation/step_guard.h"
#include "simulation/scenes.h"

namespace liver_sim {
namespace {

// --- Bounds --------------------------------------------------------------------------------------

// Each bound refuses the value just beyond it with the field's name and the bound in the
// message, and accepts the bound itself.
template <typename Options, typename Set>
void expect_bound(Options o, const Set& set, double inside, double outside, const std::string& field,
                  const std::string& bound) {
  set(o, inside);
  EXPECT_EQ(validate(o), "") << field << " = " << inside;
  set(o, outside);
  const std::string error = validate(o);
  EXPECT_NE(error.find(field), std::string::npos) << error;
  EXPECT_NE(error.find(bound), std::string::npos) << error;
}

TEST(Bounds, EachFieldThatSizesWorkOrLiesBeyondTissueHasOne) {
  expect_bound(ParenchymaOptions{}, [](auto& o, double v) { o.young_modulus = v; }, 1e9, 1.1e9,
               "parenchyma.young_modulus", "1e9");
  expect_bound(ParenchymaOptions{}, [](auto& o, double v) { o.density = v; }, 1e5, 1.1e5, "parenchyma.density", "1e5");
  expect_bound(CapsuleOptions{}, [](auto& o, double v) { o.young_modulus = v; }, 1e10, 1e300, "capsule.young_modulus",
               "1e10");
  expect_bound(CapsuleOptions{}, [](auto& o, double v) { o.thickness = v; }, 1e-3, 1.0, "capsule.thickness", "1e-3");
  expect_bound(SolverOptions{}, [](auto& o, double v) { o.dt = v; }, 10, 11, "solver.dt", "10");
  expect_bound(SolverOptions{}, [](auto& o, double v) { o.steps = static_cast<int>(v); }, 1e6, 1e6 + 1, "solver.steps", "1e6");
  expect_bound(SolverOptions{}, [](auto& o, double v) { o.max_iterations = static_cast<int>(v); }, 1e4, 1e4 + 1,
               "solver.max_iterations", "10000");
  expect_bound(SolverOptions{}, [](auto& o, double v) { o.time_budget = v; }, std::numeric_limits<double>::infinity(), 0,
               "solver.time_budget", "(0, inf]");
  expect_bound(SolverOptions{}, [](auto& o, double v) { o.capped_residual = v; }, std::numeric_limits<double>::infinity(),
               0, "solver.capped_residual", "(0, inf]");
  expect_bound(ContactOptions{}, [](auto& o, double v) { o.alarm_distance = v; }, 0.01, 0.02, "contact.alarm_distance",
               "0.01");
  expect_bound(ContactOptions{}, [](auto& o, double v) { o.friction = v; }, 10, 11, "contact.friction", "10");
  expect_bound(ContactOptions{}, [](auto& o, double v) { o.max_iterations = static_cast<int>(v); }, 1e6, 1e6 + 1,
               "contact.max_iterations", "1e6");
  expect_bound(RegistrationOptions{}, [](auto& o, double v) { o.max_points = static_cast<int>(v); }, 1e5, 1e5 + 1,
               "registration.max_points", "100000");
  expect_bound(RegistrationOptions{}, [](auto& o, double v) { o.voxel_size = v; }, 0.1, 0.2, "registration.voxel_size", "0.1");
  expect_bound(RegistrationOptions{}, [](auto& o, double v) { o.correspondence_updates = static_cast<int>(v); }, 100, 101,
               "registration.correspondence_updates", "100");
  expect_bound(RegistrationOptions{}, [](auto& o, double v) { o.newton_iterations = static_cast<int>(v); }, 100, 101,
               "registration.newton_iterations", "100");
  expect_bound(RegistrationOptions{}, [](auto& o, double v) { o.uncertainty.patch_spacing = v; }, 1e-3, 0.5e-3,
               "registration.uncertainty.patch_spacing", "1e-3");

  InstrumentOptions probe;
  probe.name = "p";
  expect_bound(probe, [](auto& o, double v) { o.radius = v; }, 0.05, 1e9, "instruments.p.radius", "0.05");
  expect_bound(probe, [](auto& o, double v) { o.radius = v; }, 1e-4, 1e-9, "instruments.p.radius", "1e-4");
  expect_bound(probe, [](auto& o, double v) { o.position.x() = v; }, 100, 1e300, "instruments.p.pose", "100");
  InstrumentOptions shaft = probe;
  shaft.type = Type::Shaft;
  expect_bound(shaft, [](auto& o, double v) { o.length = v; }, 0.5, 0.6, "instruments.p.length", "0.5");
  InstrumentOptions tube = probe;
  tube.type = Type::Tube;
  expect_bound(tube, [](auto& o, double v) { o.suction = v; }, 101325, 2e5, "instruments.p.suction", "101325");
  expect_bound(tube, [](auto& o, double v) { o.outer_radius = v; }, 0.05, 1.0, "instruments.p.outer_radius", "0.05");
  expect_bound(tube, [](auto& o, double v) { o.trajectory.assign(static_cast<size_t>(v), {}); }, 1, 10001,
               "instruments.p.trajectory", "10000");
  EXPECT_EQ(cloud_size_error(kMaxCloudPoints), "");
  EXPECT_NE(cloud_size_error(kMaxCloudPoints + 1).find(std::to_string(kMaxCloudPoints)), std::string::npos);
}

// A model in contact refuses a capsule of 1e300 Pa or 1 m, a probe of radius 1e9 m, a pose at
// 1e300 m, solver options beyond their bounds and a seventeenth instrument, and its state holds
// the same bits after the refusals; the next step converges.
TEST(Bounds, RefusalsChangeNothing) {
  Scene s = scene_with(Type::Probe);
  LiverModel m(load_scene_mesh(s), s);
  for (int k = 0; k < 2; ++k) ASSERT_TRUE(m.step().converged());
  const std::vector<double> before = m.observable_state();
  const InstrumentOptions probe = m.instrument(0);
  const CapsuleOptions capsule = m.capsule();

  CapsuleOptions c = capsule;
  c.young_modulus = 1e300;
  EXPECT_NE(m.set_capsule(c).find("capsule.young_modulus"), std::string::npos);
  c = capsule;
  c.thickness = 1.0;
  EXPECT_NE(m.set_capsule(c).find("capsule.thickness"), std::string::npos);
  EXPECT_EQ(m.capsule().young_modulus, capsule.young_modulus);
  EXPECT_EQ(m.capsule().thickness, capsule.thickness);

  InstrumentOptions o = probe;
  o.radius = 1e9;
  EXPECT_THROW(m.update_instrument(0, o), std::invalid_argument);
  o = probe;
  o.trajectory.clear();
  o.position = Eigen::Vector3d(1e300, 0, 0);
  EXPECT_THROW(m.update_instrument(0, o), std::invalid_argument);
  EXPECT_EQ(m.instrument(0).radius, probe.radius);
  EXPECT_EQ(m.instrument(0).trajectory.size(), probe.trajectory.size());

  SolverOptions solver = m.solver_options();
  solver.max_iterations = 1000000000;
  EXPECT_NE(m.set_solver_options(solver).find("solver.max_iterations"), std::string::npos);
  EXPECT_EQ(m.solver_options().max_iterations, s.solver.max_iterations);
  EXPECT_TRUE(same_bits(m.observable_state(), before));

  for (int i = m.num_instruments(); i < kMaxInstruments; ++i) {
    InstrumentOptions far;  // out of the scene
    far.name = "far" + std::to_string(i);
    far.enabled = false;
    m.add_instrument(far);
  }
  InstrumentOptions extra;
  extra.name = "one too many";
  extra.enabled = false;
  const std::vector<double> full = m.observable_state();
  EXPECT_THROW(m.add_instrument(extra), std::invalid_argument);
  EXPECT_EQ(m.num_instruments(), kMaxInstruments);
  EXPECT_EQ(m.find_instrument("one too many"), -1);
  EXPECT_TRUE(same_bits(m.observable_state(), full));
  EXPECT_TRUE(m.step().converged());
}

// The next step throws std::length_error naming `what` and leaves the model to the last bit.
void expect_contact_bound_refuses_step(LiverModel& m, const std::string& what) {
  const std::vector<double> before = m.observable_state();
  try {
    m.step();
    ADD_FAILURE() << "the step took " << m.contact().contacts().size() << " contact points";
  } catch (const std::length_error& e) {
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
  EXPECT_TRUE(same_bits(m.observable_state(), before));
}

// A wire of 0.1 mm lying 4 mm along the top face (every surface sample within the alarm
// distance, 0.05 mm apart, is a contact point) is refused at detection: the step throws, the
// state keeps its bits, and the wire lifted off, the next step converges. Without the bound the
// step takes its 2,913 contact points, an 8,739 x 8,739 Delassus operator, and 15 s (checked:
// the test then fails).
TEST(Bounds, TooManyContactPointsAreRefused) {
  Scene s = scene_with(Type::Probe);
  LiverModel m(load_scene_mesh(s), s);
  for (int k = 0; k < 2; ++k) ASSERT_TRUE(m.step().converged());
  InstrumentOptions wire;
  wire.name = "wire";
  wire.type = Type::Shaft;
  wire.radius = 1e-4;
  wire.length = 0.004;
  wire.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));  // along x
  wire.position = Eigen::Vector3d(0.002, 0.0075, 0.015 + 0.5 * wire.radius);
  const int k = m.add_instrument(wire);
  expect_contact_bound_refuses_step(m, "instruments.wire");
  wire.position.z() += 0.005;
  m.update_instrument(k, wire);
  EXPECT_TRUE(m.step().converged());
}

// The detection stops sampling the surface near the instruments at kMaxContactSamples, before
// it counts their contact points: a 0.1 mm wire of 5 cm hovering 5 mm above a 5 cm slab (5 mm
// triangles) within a 10 mm alarm distance, which touches nothing. Killed by the bound left out
// (tried: all 909,889 samples within the alarm distance became contact points before that
// bound refused the step).
TEST(Bounds, TooManySurfaceSamplesAreRefused) {
  Scene s;
  s.parenchyma.young_modulus = 3000;
  s.parenchyma.poisson_ratio = 0.45;
  Region bottom;
  bottom.kind = Region::Kind::Box;
  bottom.min = Eigen::Vector3d::Constant(-1);
  bottom.max = Eigen::Vector3d(1, 1, 1e-9);
  s.fixed.push_back(bottom);
  s.contact.alarm_distance = 0.01;
  const double length = 0.05;
  LiverModel m(make_box_mesh({length, length, 0.02}, {10, 10, 1}), s);
  ASSERT_TRUE(m.step().converged());
  InstrumentOptions wire;
  wire.name = "wire";
  wire.type = Type::Shaft;
  wire.radius = 1e-4;
  wire.length = length;
  wire.orientation = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitX());
  wire.position = Eigen::Vector3d(0, length / 2, 0.02 + wire.radius + 0.005);
  m.add_instrument(wire);
  expect_contact_bound_refuses_step(m, "surface samples near instruments.wire");
}

// A model full of instruments takes a new one in the slot of one withdrawn since the last step,
// name and type included (a tube where the probe was: it then gets a pressure load), and
// refuses to replace one in the scene; the new one acts. Without replace_instrument a node
// that saw 16 names, each declared and removed, refused every new one.
TEST(Bounds, AWithdrawnInstrumentsSlotTakesANewOne) {
  Scene s = scene_with(Type::Probe);
  LiverModel m(load_scene_mesh(s), s);
  for (int k = 0; k < 2; ++k) ASSERT_TRUE(m.step().converged());
  ASSERT_GT(m.instrument_reaction(0).contacts, 0);
  for (int i = m.num_instruments(); i < kMaxInstruments; ++i) {
    InstrumentOptions far;
    far.name = "far" + std::to_string(i);
    far.enabled = false;
    m.add_instrument(far);
  }
  InstrumentOptions tube = scene_with(Type::Tube).instruments[0];
  tube.name = "tube";
  tube.trajectory.clear();
  tube.position = Eigen::Vector3d(0.0075, 0.0075, 0.015);  // on the top face's centre
  EXPECT_THROW(m.replace_instrument(0, tube), std::invalid_argument) << "the probe is in the scene";
  InstrumentOptions probe = m.instrument(0);
  probe.enabled = false;
  m.update_instrument(0, probe);
  EXPECT_THROW(m.replace_instrument(0, tube), std::invalid_argument) << "in the scene at the last step";
  ASSERT_TRUE(m.step().converged());
  EXPECT_EQ(m.instrument_reaction(0).contacts, 0);
  m.replace_instrument(0, tube);
  EXPECT_EQ(m.num_instruments(), kMaxInstruments);
  EXPECT_EQ(m.find_instrument("tube"), 0);
  EXPECT_EQ(m.find_instrument(probe.name), -1);
  for (int k = 0; k < 3; ++k) ASSERT_NE(m.step().status, StepResult::Status::Diverged);
  EXPECT_GT(m.instrument_reaction(0).contacts, 0) << "the tube acts";
}

// The farthest pose the bounds allow, 100 m away and back, in single steps: the stage count
// stays at its cap (the travel over a quarter of the radius is 2e5), the state stays finite and
// the probe comes back into contact.
TEST(Bounds, TheFarthestJumpIsStagedWithinTheCap) {
  Scene s = load_scene(source("config/scenes/probe_cube.yaml"));
  s.mesh.box_divisions = Eigen::Vector3i(4, 4, 4);
  InstrumentOptions probe;
  probe.name = "probe";
  probe.radius = 0.002;
  probe.position = Eigen::Vector3d(0.0075, 0.0075, 0.0165);
  s.instruments.push_back(probe);
  LiverModel m(load_scene_mesh(s), s);
  ASSERT_TRUE(m.step().converged());
  ASSERT_GT(m.instrument_reaction(0).contacts, 0);
  for (double x : {100.0, 0.0075}) {
    probe.position.x() = x;
    m.update_instrument(0, probe);
    const StepResult r = m.step();
    EXPECT_TRUE(r.converged()) << r.message;
    EXPECT_TRUE(m.finite_state());
  }
  EXPECT_GT(m.instrument_reaction(0).contacts, 0);
}

}  // namespace
}  // namespace liver_sim
