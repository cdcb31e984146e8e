// What keeps the model serving in the OR: a rolled-back step leaves the whole state as it was
// (every instrument type, every way a step fails), a step stops at its time budget with a state
// the next step can continue from, and inputs beyond their documented bounds are refused with a
// message naming the field and the bound, changing nothing.
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

namespace liver_sim {
namespace {

using Fault = NewtonStepper::InjectedFault;
using Type = InstrumentOptions::Type;

std::string source(const std::string& file) { return std::string(LIVER_SIM_SOURCE_DIR) + "/" + file; }

// An instrument of `type` pressing further into the top face of a 15 mm cube at every step of
// the scene's pseudo-time, so that each step has work to do (tip positions in mm).
InstrumentOptions pressing(Type type, const Eigen::Vector3d& from_mm, const Eigen::Vector3d& to_mm, double until) {
  InstrumentOptions o;
  o.name = "instrument";
  o.type = type;
  o.radius = 0.002;
  o.length = 0.01;
  o.trajectory.resize(2);
  o.trajectory[0].position = 1e-3 * from_mm;
  o.trajectory[1].t = until;
  o.trajectory[1].position = 1e-3 * to_mm;
  o.position = o.trajectory[0].position;
  return o;
}

// The probe cube (6 x 6 x 6 hexahedra, friction 0.3) with one instrument of the type, or the
// aspiration tube's scene (a tube with 3 kPa of suction, as the issue measured it) pressed down.
Scene scene_with(Type type) {
  if (type == Type::Tube) {
    Scene s = load_scene(source("config/scenes/aspiration_tube.yaml"));
    s.mesh.box_divisions = Eigen::Vector3i(6, 6, 6);
    InstrumentOptions& tube = s.instruments[0];
    tube.trajectory.resize(2);
    tube.trajectory[0].position = tube.position;
    tube.trajectory[1].t = 0.05;
    tube.trajectory[1].position = tube.position - Eigen::Vector3d(0, 0, 0.5e-3);
    return s;
  }
  Scene s = load_scene(source("config/scenes/probe_cube.yaml"));
  s.mesh.box_divisions = Eigen::Vector3i(6, 6, 6);
  switch (type) {
    case Type::Probe:  // a 2 mm sphere, 0.3 mm further per step
      s.instruments.push_back(pressing(type, {7.5, 7.5, 17}, {7.5, 7.5, 14}, 0.01));
      break;
    case Type::Shaft:  // a 2 mm rod lying across the top face, turned onto x, pressed down
      s.instruments.push_back(pressing(type, {2.5, 7.5, 17}, {2.5, 7.5, 14}, 0.01));
      s.instruments.back().orientation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));
      for (auto& k : s.instruments.back().trajectory) k.orientation = s.instruments.back().orientation;
      break;
    case Type::Grasper:  // closes on the top face's centre and lifts it 0.2 mm per step
      s.instruments.push_back(pressing(type, {7.5, 7.5, 15}, {7.5, 7.5, 17}, 0.01));
      s.instruments.back().trajectory[0].closed = true;
      break;
    case Type::Tube:
      break;
  }
  return s;
}

const char* name(Type type) {
  switch (type) {
    case Type::Probe: return "probe";
    case Type::Shaft: return "shaft";
    case Type::Tube: return "tube";
    case Type::Grasper: return "grasper";
  }
  return "";
}

// How a step is made to fail: an input that leads there (a NaN load scale), or the stepper's test
// hook (an exception, an allocation failure, a NaN in the update, a negative pivot).
enum class Failure { NonFiniteLoad, Exception, OutOfMemory, NonFiniteUpdate, NotPositiveDefinite };

struct Case {
  Type type;
  Failure failure;
};

std::string case_name(const testing::TestParamInfo<Case>& info) {
  static const char* failures[] = {"NonFiniteLoad", "Exception", "OutOfMemory", "NonFiniteUpdate", "NotPositiveDefinite"};
  return std::string(name(info.param.type)) + "_" + failures[static_cast<int>(info.param.failure)];
}

class Rollback : public testing::TestWithParam<Case> {};

// Three steps into contact, then a step that fails: the whole observable state after it (the
// positions, velocities, time, each instrument's pose and reaction, every contact with its force,
// the suction load, the element rotations and their warm starts) holds the same bits as before
// it, and the instrument still presses with the force it had. The next step is then the one a
// twin model that never failed takes (time not advanced, the instrument not left at a staged
// pose): its positions agree to the solver's tolerance (a residual of 1e-8; after a negative
// pivot the factor is refreshed, and the Newton path differs: 2e-6 of the displacement measured),
// far below the 0.05-0.3 mm the instruments move per step.
// Kills a rollback that restores the positions alone (the reaction and contacts were lost: the
// issue's 0 N over 0 contacts in the tube scene), and one that advances time.
TEST_P(Rollback, RestoresTheWholeStateBitwise) {
  const Case c = GetParam();
  const Scene s = scene_with(c.type);
  LiverModel m(load_scene_mesh(s), s), twin(load_scene_mesh(s), s);
  for (int k = 0; k < 3; ++k) {
    const StepResult r = m.step();
    ASSERT_TRUE(r.converged()) << "step " << k << ": " << r.message;
    ASSERT_TRUE(twin.step().converged());
  }
  const InstrumentReaction reaction = m.instrument_reaction(0);
  ASSERT_GT(reaction.contacts, 0);
  ASSERT_GT(reaction.force.norm(), 0.0);
  const std::vector<double> before = m.observable_state();

  switch (c.failure) {
    case Failure::NonFiniteLoad: {
      m.set_load_scale(std::numeric_limits<double>::quiet_NaN());
      const StepResult r = m.step();
      EXPECT_EQ(r.status, StepResult::Status::Diverged);
      EXPECT_EQ(r.message.rfind("non-finite residual", 0), 0u) << r.message;
      m.set_load_scale(1.0);
      break;
    }
    case Failure::Exception:
      m.stepper().inject_fault(Fault::Exception);
      EXPECT_THROW(m.step(), std::runtime_error);
      break;
    case Failure::OutOfMemory:
      m.stepper().inject_fault(Fault::OutOfMemory);
      EXPECT_THROW(m.step(), std::bad_alloc);
      break;
    case Failure::NonFiniteUpdate: {
      m.stepper().inject_fault(Fault::NonFinite);
      const StepResult r = m.step();
      EXPECT_EQ(r.status, StepResult::Status::Diverged);
      EXPECT_EQ(r.message.rfind("non-finite Newton update", 0), 0u) << r.message;
      break;
    }
    case Failure::NotPositiveDefinite: {
      m.stepper().inject_fault(Fault::NotPositiveDefinite);
      const StepResult r = m.step();
      EXPECT_EQ(r.status, StepResult::Status::Diverged);
      EXPECT_EQ(r.message.rfind("tangent matrix is not positive definite", 0), 0u) << r.message;
      break;
    }
  }
  EXPECT_TRUE(same_bits(m.observable_state(), before));
  EXPECT_EQ(m.instrument_reaction(0).contacts, reaction.contacts);
  EXPECT_EQ(m.instrument_reaction(0).force, reaction.force);

  const StepResult next = m.step();
  ASSERT_TRUE(next.converged()) << next.message;
  ASSERT_TRUE(twin.step().converged());
  EXPECT_EQ(m.time(), twin.time());
  EXPECT_LE((m.positions() - twin.positions()).cwiseAbs().maxCoeff(), 1e-5 * twin.max_displacement());
}

std::vector<Case> all_cases() {
  std::vector<Case> v;
  for (Type t : {Type::Probe, Type::Shaft, Type::Tube, Type::Grasper})
    for (Failure f : {Failure::NonFiniteLoad, Failure::Exception, Failure::OutOfMemory, Failure::NonFiniteUpdate,
                      Failure::NotPositiveDefinite})
      v.push_back({t, f});
  return v;
}

INSTANTIATE_TEST_SUITE_P(EveryInstrumentEveryFailure, Rollback, testing::ValuesIn(all_cases()), case_name);

// --- Time budget ---------------------------------------------------------------------------------

// The aspiration cube (4 x 4 x 4 hexahedra, capsule, 3 kPa of suction) in static mode.
Scene aspiration_cube() {
  Scene s = load_scene(source("config/scenes/aspiration_cube.yaml"));
  s.mesh.box_divisions = Eigen::Vector3i(4, 4, 4);
  return s;
}

// The node's barrier with its test hook at every step (~test_fault_every 1): the cycle's first four
// steps fail and roll back, and the fifth is held up for 0.3 s, which is no failure but says so in
// its message: the soak finds the held-up steps by that text and judges the frame rate over the
// time they leave. Kills a held-up step that does not say so (tried: the append in
// StepGuard::step dropped; the soak would count the delays against the node) and a step that
// says so without being held up (tried: any step after a hold-up told, the stepper's count
// compared with 0 instead of with its value before the step).
TEST(StepGuard, AnInjectedHoldUpSaysSoAndNoOtherStepDoes) {
  const Scene s = scene_with(Type::Probe);
  LiverModel m(load_scene_mesh(s), s);
  StepGuard guard;
  guard.set_test_fault_every(1);
  for (int k = 0; k < 7; ++k) {
    if (k == 5) guard.set_test_fault_every(0);
    const StepResult r = guard.step(m, [&] { return m.step(); });
    const bool told = r.message.find(StepGuard::kHeldUpText) != std::string::npos;
    EXPECT_EQ(told, k == 4) << "step " << k << ": " << r.message;
    EXPECT_EQ(r.status == StepResult::Status::Diverged, k < 4) << "step " << k << ": " << r.message;
  }
}

// A budget that every step exceeds at once: each step does its one guaranteed Newton iteration
// and stops, NotConverged ("time budget"); frame after frame the model still reaches the
// equilibrium an unlimited solve finds, to the solver's tolerance.
// Kills a budget that stops before the first iteration (no frame ever moves) and one that keeps
// nothing (each frame starts again from rest).
TEST(TimeBudget, OneIterationPerStepStillReachesTheEquilibrium) {
  Scene s = aspiration_cube();
  LiverModel unlimited(load_scene_mesh(s), s);
  ASSERT_TRUE(unlimited.step().converged());
  s.solver.time_budget = 1e-9;
  LiverModel m(load_scene_mesh(s), s);
  StepResult r;
  r.status = StepResult::Status::NotConverged;
  int steps = 0;
  for (; steps < 50 && !r.converged(); ++steps) {
    r = m.step();
    ASSERT_NE(r.status, StepResult::Status::Diverged) << r.message;
    if (!r.converged()) {
      EXPECT_EQ(r.iterations, 1);
      EXPECT_TRUE(r.out_of_time);
      EXPECT_EQ(r.message.rfind("time budget", 0), 0u) << r.message;
    }
  }
  ASSERT_TRUE(r.converged()) << "after " << steps << " steps: " << r.message;
  EXPECT_GT(steps, 2);
  EXPECT_LE((m.positions() - unlimited.positions()).cwiseAbs().maxCoeff(), 1e-6 * unlimited.max_displacement());
}

// A probe that appears 10 mm above the probe cube and is asked 12 mm down in one step: the step
// moves it in stages of a quarter of its radius (16 at most). Out of time after the first stage
// (still out of contact), the step ends there: the probe stands at the first stage's pose, 1/16
// of the way from where it was to its target, not at the target.
// Kills a budget that leaves the instruments at their target while the tissue stopped short.
TEST(TimeBudget, AStepOutOfTimeLeavesTheInstrumentAtItsStage) {
  Scene s = load_scene(source("config/scenes/probe_cube.yaml"));
  s.mesh.box_divisions = Eigen::Vector3i(4, 4, 4);
  s.solver.time_budget = 1e-9;
  InstrumentOptions probe;
  probe.name = "probe";
  probe.radius = 0.002;
  probe.position = Eigen::Vector3d(0.0075, 0.0075, 0.027);
  s.instruments.push_back(probe);
  LiverModel m(load_scene_mesh(s), s);
  ASSERT_TRUE(m.step().converged());
  const Eigen::Vector3d start = m.contact().pose(0).translation();
  ASSERT_NEAR(start.z(), 0.027, 1e-12);
  probe.position.z() = 0.015;
  m.update_instrument(0, probe);
  const StepResult r = m.step();
  EXPECT_TRUE(r.out_of_time) << r.message;
  const Eigen::Vector3d expected = start + (probe.position - start) / 16;
  EXPECT_LE((m.contact().pose(0).translation() - expected).norm(), 1e-12)
      << m.contact().pose(0).translation().transpose();
}

// A model of scene s at equilibrium under `scale` of its loads, then given all of them, with
// `iterations` Newton iterations a step and a time budget of `budget` s, so that its next step
// starts on the factor of the partial load. `factorization_s`: the mean factorisation of its
// first step.
std::unique_ptr<LiverModel> partly_loaded(const Scene& s, double scale, int iterations, double budget,
                                          double* factorization_s = nullptr) {
  auto m = std::make_unique<LiverModel>(load_scene_mesh(s), s);
  m->set_load_scale(scale);
  const StepResult r = m->step();
  EXPECT_TRUE(r.converged());
  if (factorization_s) *factorization_s = 1e-3 * r.timing.factorization_ms / r.factorizations;
  SolverOptions o = s.solver;
  o.max_iterations = iterations;
  o.time_budget = budget;
  EXPECT_EQ(m->set_solver_options(o), "");
  m->set_load_scale(1.0);
  return m;
}

// A step of `late` whose refresh of the factor needs more time than it has left (a budget of a
// quarter of the factorisation its own first step timed): one iteration, no factorisation, out
// of time, where `one` (an unlimited step of one iteration) ended.
void step_past_a_refresh(LiverModel& late, double factorization_s, const LiverModel& one) {
  SolverOptions o = late.solver_options();
  o.time_budget = 0.25 * factorization_s;
  ASSERT_EQ(late.set_solver_options(o), "");
  const StepResult deferred = late.step();
  EXPECT_EQ(deferred.status, StepResult::Status::NotConverged) << deferred.message;
  EXPECT_TRUE(deferred.out_of_time);
  EXPECT_EQ(deferred.iterations, 1);
  EXPECT_EQ(deferred.factorizations, 0);
  EXPECT_EQ(late.positions(), one.positions());
}

// Modified Newton on the factor of a tenth of the suction, asked for the full suction in one
// iteration: that factor finds no descent, and the iteration is redone on a new factor. With an
// unlimited budget the step refactorises and moves. Past its budget the step must not start the
// factorisation: it ends where the iteration started (not rolled back, out of time) and the next
// step begins with the factorisation, doing what the refresh would have done.
// Kills a refresh that ignores the budget (a factorisation in the first step past it), a
// deferral that keeps the old factor (none in the next step) and one that keeps the trial point
// (each tried).
TEST(TimeBudget, ANoDescentRefreshPastTheBudgetWaitsForTheNextStep) {
  Scene s = aspiration_cube();
  s.solver.strategy = SolverOptions::Strategy::ModifiedNewton;
  auto at_a_tenth = [&](double budget) { return partly_loaded(s, 0.1, 1, budget); };
  std::unique_ptr<LiverModel> unlimited = at_a_tenth(std::numeric_limits<double>::infinity());
  const Eigen::VectorXd start = unlimited->positions();
  const StepResult refreshed = unlimited->step();
  ASSERT_EQ(refreshed.factorizations, 1) << "the old factor found a descent: the scene no longer tests the refresh";
  ASSERT_GT((unlimited->positions() - start).norm(), 0);

  std::unique_ptr<LiverModel> late = at_a_tenth(1e-9);
  ASSERT_EQ(late->positions(), start);
  const StepResult deferred = late->step();
  EXPECT_EQ(deferred.status, StepResult::Status::NotConverged) << deferred.message;
  EXPECT_TRUE(deferred.out_of_time);
  EXPECT_EQ(deferred.factorizations, 0);
  EXPECT_EQ(late->positions(), start);
  const StepResult next = late->step();
  EXPECT_EQ(next.factorizations, 1);
  EXPECT_LE((late->positions() - unlimited->positions()).cwiseAbs().maxCoeff(),
            1e-9 * (unlimited->positions() - start).cwiseAbs().maxCoeff());
}

// Modified Newton on the factor of 0.6 of the suction, asked for the full suction in two
// iterations: the first finds a descent but contracts too little, and the second would start
// on a new factor. Past the time that factorisation needs (the budget is a quarter of the mean
// factorisation of the model's first step, and the first iteration takes a tenth of one), the
// step ends after the first iteration, out of time, where an unlimited one-iteration step ends;
// the next step begins with the factorisation.
// Kills a refresh that ignores the budget (a factorisation in the first step; mutation R8). With
// the rule left out, the step still ends out of time if its first iteration alone outlasted the
// budget: on a shared machine a missed kill. The rule fails to fire only if the model's last
// factorisation took under a quarter of its first step's mean.
TEST(TimeBudget, ARefreshAfterTheFirstIterationThatDoesNotFitStartsTheNextStep) {
  Scene s = aspiration_cube();
  s.mesh.box_divisions = Eigen::Vector3i(12, 12, 12);  // a factorisation ten times an iteration
  s.solver.strategy = SolverOptions::Strategy::ModifiedNewton;
  double factorization_s = 0;  // of the last model's first step
  auto at_six_tenths = [&](int iterations, double budget) {
    return partly_loaded(s, 0.6, iterations, budget, &factorization_s);
  };
  const double unlimited = std::numeric_limits<double>::infinity();
  std::unique_ptr<LiverModel> one = at_six_tenths(1, unlimited);
  ASSERT_EQ(one->step().factorizations, 0) << "the old factor found no descent: the scene tests the redo, not the refresh";
  std::unique_ptr<LiverModel> two = at_six_tenths(2, unlimited);
  ASSERT_EQ(two->step().factorizations, 1) << "the first iteration contracted well: the scene no longer tests the refresh";

  std::unique_ptr<LiverModel> late = at_six_tenths(2, unlimited);
  step_past_a_refresh(*late, factorization_s, *one);
  EXPECT_EQ(late->step().factorizations, 1);
}

// The same refresh at the start of a later stage: a probe far above the cube (out of contact)
// moved 1.5 stage lengths in one step, two stages of one iteration each, the first on the factor
// of 0.6 of the suction. Its iteration contracts too little, and the second stage would start
// with a factorisation. Past the time that factorisation needs (as above), the step ends after
// the first stage, out of time: the tissue where an unlimited one-stage step leaves it, the probe
// at the first stage's pose; the next step begins with the factorisation.
// Kills a stage that starts with a factorisation the time left cannot hold (the rule left out:
// the step factorises in its second stage and moves the probe to its target; tried). A missed
// kill only if the first stage alone outlasted the budget, as above.
TEST(TimeBudget, ARefreshThatDoesNotFitAtALaterStageEndsTheStepBetweenStages) {
  Scene s = aspiration_cube();
  s.mesh.box_divisions = Eigen::Vector3i(12, 12, 12);
  s.solver.strategy = SolverOptions::Strategy::ModifiedNewton;
  InstrumentOptions probe;
  probe.name = "probe";
  probe.radius = 0.002;
  probe.position = Eigen::Vector3d(0.0075, 0.0075, 0.05);
  s.instruments.push_back(probe);
  const Eigen::Vector3d start = probe.position;
  const Eigen::Vector3d target = start - Eigen::Vector3d(0, 0, 1.5 * 0.25 * probe.radius);  // stages of a quarter radius: two
  double factorization_s = 0;
  auto at_six_tenths = [&](const Eigen::Vector3d& to) {
    auto m = partly_loaded(s, 0.6, 1, std::numeric_limits<double>::infinity(), &factorization_s);
    InstrumentOptions moved = probe;
    moved.position = to;
    m->update_instrument(0, moved);
    return m;
  };
  std::unique_ptr<LiverModel> unlimited = at_six_tenths(target);
  const StepResult both = unlimited->step();
  ASSERT_EQ(both.factorizations, 1) << "the first stage contracted well: the scene no longer tests the refresh";
  ASSERT_EQ(both.contacts, 0);
  ASSERT_LE((unlimited->contact().pose(0).translation() - target).norm(), 1e-12);
  std::unique_ptr<LiverModel> one = at_six_tenths(start);  // one stage, one iteration
  ASSERT_EQ(one->step().factorizations, 0);

  std::unique_ptr<LiverModel> late = at_six_tenths(target);
  step_past_a_refresh(*late, factorization_s, *one);
  EXPECT_LE((late->contact().pose(0).translation() - 0.5 * (start + target)).norm(), 1e-12)
      << late->contact().pose(0).translation().transpose();
  EXPECT_EQ(late->step().factorizations, 1);
}

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
