// Steps with a probe in contact: dynamic presses settle on the static equilibrium, a factor
// serves the iterations after the one that made it, damped haptic frames close new gaps, and
// budgeted ones keep a cut contact update and solve their contacts only as far as they need.
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

// A probe (4 mm) lowered 2 mm onto a 20 mm block and pressed 1.5 mm into it within `press_time`
// (s), then held: dynamic steps of 10 ms, mass-proportional damping.
constexpr double kBlock = 0.02;

// A probe of radius r over the block's top at x = x0, `above` it, pressed `depth` into it by
// press_time, then swept along x to x1 at `speed` (m, s, m/s).
InstrumentOptions swept_probe(double r, double above, double depth, double press_time, double x0, double x1,
                              double speed) {
  InstrumentOptions p = probe("probe", Eigen::Vector3d::Zero(), r);
  for (double t : {0.0, press_time, press_time + std::abs(x1 - x0) / speed}) {
    InstrumentOptions::Keyframe f;
    f.t = t;
    f.position = Eigen::Vector3d(t <= press_time ? x0 : x1, kBlock / 2, kBlock + r - (t == 0 ? -above : depth));
    p.trajectory.push_back(f);
  }
  return p;
}
Scene dynamic_press(double press_time) {
  const double r = 0.004;
  Scene s = block_scene(3000, 0.45, 0.3);
  InstrumentOptions p = probe("probe", Eigen::Vector3d::Zero(), r);
  const Eigen::Vector3d end(kBlock / 2, kBlock / 2, kBlock + r - 0.0015);
  for (double t : {0.0, press_time}) {
    InstrumentOptions::Keyframe f;
    f.t = t;
    f.position = end + Eigen::Vector3d(0, 0, t == 0 ? 0.002 : 0.0);
    p.trajectory.push_back(f);
  }
  s.instruments.push_back(p);
  s.solver.mode = SolverOptions::Mode::Dynamic;
  s.solver.dt = 0.01;
  s.solver.rayleigh_mass = 20;
  return s;
}

// The probe's reaction at the static equilibrium at the end of the press.
double static_press_reaction(const Scene& dynamic) {
  Scene st = dynamic;
  st.solver.mode = SolverOptions::Mode::Static;
  st.solver.strategy = SolverOptions::Strategy::NewtonKrylov;
  st.solver.max_iterations = 60;
  st.solver.background_refresh = false;
  st.solver.dt = 1.0;  // the trajectory's end at the first step
  LiverModel reference(make_box_mesh({kBlock, kBlock, kBlock}, {6, 6, 6}), st);
  const StepResult r = reference.step();
  EXPECT_TRUE(r.converged()) << r.message;
  return reference.instrument_reaction(0).force.z();
}

// Dynamics: a probe pressing along a trajectory converges at every step and ends at rest on
// the same equilibrium as the static solve.
TEST(Probe, DynamicPressSettlesOnTheStaticEquilibrium) {
  const Scene s = dynamic_press(0.1);
  LiverModel dyn(make_box_mesh({kBlock, kBlock, kBlock}, {6, 6, 6}), s);
  for (int k = 0; k < 150; ++k) {
    const StepResult res = dyn.step();
    ASSERT_TRUE(res.converged()) << "step " << k << ": " << res.message;
  }
  const double reference = static_press_reaction(s);
  EXPECT_NEAR(dyn.instrument_reaction(0).force.z(), reference, 0.01 * reference);
}

// The node's frames: modified Newton, two iterations a step, its refreshes factorised in the
// background while the steps go on with the old factor (a short pause after each step gives the
// thread the time a real-time frame leaves). The press must settle where the static equilibrium
// is, the steps taking up factors from the thread. Checked to fail when the contraction rule
// asks for no background refresh, and when the refresh is never started (none taken up). A
// taken factor not counted as new (the contact's compliance cache then stays the old factor's)
// survives: the iterations correct the stale operator, and the press settles all the same.
TEST(Probe, BackgroundRefreshSettlesOnTheStaticEquilibrium) {
  Scene s = dynamic_press(0.3);
  s.solver.strategy = SolverOptions::Strategy::ModifiedNewton;
  s.solver.max_iterations = 2;
  s.solver.background_refresh = true;
  LiverModel dyn(make_box_mesh({kBlock, kBlock, kBlock}, {6, 6, 6}), s);
  int taken = 0;
  for (int k = 0; k < 200; ++k) {
    const StepResult res = dyn.step();
    ASSERT_NE(res.status, StepResult::Status::Diverged) << "step " << k << ": " << res.message;
    taken += res.background_factorizations;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  EXPECT_GT(taken, 0) << "no refresh came from the background";
  const double reference = static_press_reaction(s);
  EXPECT_NEAR(dyn.instrument_reaction(0).force.z(), reference, 0.01 * reference);
}

// Modified Newton judges its factor by the residual each iteration was asked to zero. A probe
// hovering within the alarm distance puts surface points into the contact problem without
// loading them: the iterations, and so the factor refreshes, must be those of the same run
// without it. Kills the contraction judged against the residual after the iteration (every
// other iteration then refreshes the factor: 14 factorisations in 30 steps against 1).
TEST(Probe, HoveringProbeKeepsModifiedNewtonsFactor) {
  const double L = 0.02;
  Scene s = block_scene(30000, 0.45, 0.0);
  s.loads.push_back(LoadOptions::gravity({0, 0, -9.81}));  // sags the top ~0.1 mm: never reaches the probe
  s.solver.mode = SolverOptions::Mode::Dynamic;
  s.solver.dt = 0.01;
  s.solver.strategy = SolverOptions::Strategy::ModifiedNewton;
  s.solver.max_iterations = 1;
  s.solver.tolerance = 1e-14;  // every step takes its one iteration
  LiverModel free(make_box_mesh({L, L, L}, {6, 6, 6}), s);
  LiverModel hovered(make_box_mesh({L, L, L}, {6, 6, 6}), s);
  const double gap = 0.3e-3;  // m, inside the alarm distance (0.5 mm)
  ASSERT_LT(gap, hovered.contact().options().alarm_distance);
  hovered.add_instrument(probe("probe", {L / 2, L / 2, L + 0.003 + gap}, 0.003));
  int free_factorizations = 0, hovered_factorizations = 0;
  bool candidates = false;
  for (int k = 0; k < 30; ++k) {
    const StepResult a = free.step(), b = hovered.step();
    ASSERT_NE(a.status, StepResult::Status::Diverged) << a.message;
    ASSERT_NE(b.status, StepResult::Status::Diverged) << b.message;
    free_factorizations += a.factorizations;
    hovered_factorizations += b.factorizations;
    candidates |= hovered.contact().active();
    ASSERT_EQ(b.contacts, 0) << "step " << k << ": the probe must not touch";
  }
  ASSERT_TRUE(candidates) << "the probe never came within the alarm distance";
  EXPECT_EQ(hovered_factorizations, free_factorizations);
  EXPECT_LE((hovered.positions() - free.positions()).cwiseAbs().maxCoeff(), 1e-9 * L);
}

// Modified Newton judges a factor by the iterations after the one that made it: that one's
// contraction measures how far from linear the contacts make the problem, which a newer factor
// meets as well. A probe sweeping 12 mm across the block, one iteration a step: no step
// refactorises right after one that factorised (none finds no descent here, which would), and
// the steps track converged dynamics as closely as full Newton's, which refactorises in every
// iteration (0.452 against 0.455 of the peak motion). Kills the rule judging the fresh factor
// too (16 factorisations, 6 of them right after another, against 9 and none; the same error).
TEST(Probe, AFactorServesTheIterationAfterTheOneThatMadeIt) {
  const double r = 0.002, depth = 0.001, speed = 0.02;  // m, m, m/s
  Scene s = block_scene(3000, 0.45, 0.3);
  s.instruments.push_back(swept_probe(r, 0.001, depth, 0.1, 0.004, 0.016, speed));  // lowered 2 mm, swept 12 mm
  s.solver.mode = SolverOptions::Mode::Dynamic;
  s.solver.dt = 0.01;
  s.solver.rayleigh_mass = 20;
  Scene converged = s, modified = s, full = s;
  converged.solver.strategy = SolverOptions::Strategy::NewtonKrylov;
  converged.solver.tolerance = 1e-8;
  converged.solver.max_iterations = 100;
  modified.solver.strategy = SolverOptions::Strategy::ModifiedNewton;
  full.solver.strategy = SolverOptions::Strategy::FullNewton;
  for (Scene* one : {&modified, &full}) {
    one->solver.max_iterations = 1;
    one->solver.tolerance = 1e-14;  // every step takes its one iteration
  }
  const TetMesh block = make_box_mesh({kBlock, kBlock, kBlock}, {6, 6, 6});
  LiverModel reference(block, converged), kept(block, modified), refreshed(block, full);
  int factorizations = 0, right_after = 0, contacts = 0;
  bool factorized_before = false;
  double kept_error = 0, refreshed_error = 0;
  for (int k = 0; k < 80; ++k) {
    const StepResult c = reference.step(), m = kept.step(), f = refreshed.step();
    ASSERT_TRUE(c.converged()) << "step " << k << ": " << c.message;
    ASSERT_NE(m.status, StepResult::Status::Diverged) << "step " << k << ": " << m.message;
    ASSERT_NE(f.status, StepResult::Status::Diverged) << "step " << k << ": " << f.message;
    factorizations += m.factorizations;
    if (m.factorizations > 0 && factorized_before) ++right_after;
    factorized_before = m.factorizations > 0;
    contacts += c.contacts;
    kept_error = std::max(kept_error, (kept.positions() - reference.positions()).cwiseAbs().maxCoeff());
    refreshed_error = std::max(refreshed_error, (refreshed.positions() - reference.positions()).cwiseAbs().maxCoeff());
  }
  ASSERT_GT(contacts, 0) << "the probe never touched the block";
  ASSERT_GT(factorizations, 1) << "the sweep never asked for a new factor";
  EXPECT_EQ(right_after, 0);
  EXPECT_LE(kept_error, 1.01 * refreshed_error);
}

// Haptic frames (1 ms) with stiffness-proportional damping (b = 0.02 s: the step's matrix is
// 21 K + M/dt^2): a 2 mm probe lowered 1.5 mm onto a block with a capsule, swept 8 mm at 3 cm/s.
Scene haptic_probe_sweep() {
  Scene s = block_scene(3500, 0.45, 0.3);
  s.capsule.enabled = true;
  s.instruments.push_back(swept_probe(0.002, 0.0005, 0.001, 0.03, 0.006, 0.014, 0.03));
  s.solver.mode = SolverOptions::Mode::Dynamic;
  s.solver.dt = 0.001;
  s.solver.rayleigh_stiffness = 0.02;
  return s;
}

// The haptic probe sweep (300 frames) with `tracked`'s solver against converged dynamics.
struct HapticSweep {
  double error = 0, peak = 0, gap = 0;  // m: the largest distance to converged dynamics, motion, gap
  int contacts = 0;                     // loaded contacts of the converged frames, summed
  long sweeps = 0;                      // Gauss-Seidel sweeps of the frames' contact solves
  int out_of_time = 0;                  // frames that ended out of time
};
HapticSweep haptic_sweep(const Scene& tracked) {
  Scene converged = tracked;
  converged.solver.strategy = SolverOptions::Strategy::NewtonKrylov;
  converged.solver.tolerance = 1e-8;
  converged.solver.max_iterations = 100;
  converged.solver.time_budget = std::numeric_limits<double>::infinity();
  const TetMesh block = make_box_mesh({kBlock, kBlock, kBlock}, {6, 6, 6});
  LiverModel reference(block, converged), model(block, tracked);
  const Eigen::VectorXd rest = reference.positions();
  HapticSweep out;
  for (int k = 0; k < 300 && !::testing::Test::HasFailure(); ++k) {
    const StepResult c = reference.step(), m = model.step();
    // One step stops at its iteration cap, 2e-8 from equilibrium.
    EXPECT_TRUE(c.converged() || c.residual <= 1e-7) << "step " << k << ": " << c.message;
    EXPECT_NE(m.status, StepResult::Status::Diverged) << "step " << k << ": " << m.message;
    out.contacts += c.contacts;
    out.sweeps += m.contact_sweeps;
    out.peak = std::max(out.peak, (reference.positions() - rest).cwiseAbs().maxCoeff());
    out.error = std::max(out.error, (model.positions() - reference.positions()).cwiseAbs().maxCoeff());
    out.gap = std::max(out.gap, model.contact().violation(model.positions()));
    out.out_of_time += m.out_of_time;
  }
  return out;
}

// The haptic sweep's frames: modified Newton, one iteration a frame.
Scene haptic_frames(double time_budget) {
  Scene s = haptic_probe_sweep();
  s.solver.strategy = SolverOptions::Strategy::ModifiedNewton;
  s.solver.max_iterations = 1;
  s.solver.tolerance = 1e-14;  // every step takes its one iteration
  s.solver.time_budget = time_budget;
  s.solver.capped_residual = std::numeric_limits<double>::infinity();  // no iteration past the cap
  return s;
}

// Every frame must end with its gaps closed to the contact tolerance (Signorini) and within 1% of
// the peak motion of converged dynamics (full Newton, a fresh factor every frame: 0.07%). Kills
// dropping the redo of a contact update that the line search cut short on a kept factor: gaps of
// 9 um then stay open for frames, 2.3% of the motion.
TEST(Probe, DampedHapticFramesCloseNewGaps) {
  const HapticSweep run = haptic_sweep(haptic_frames(std::numeric_limits<double>::infinity()));
  ASSERT_GT(run.contacts, 0) << "the probe never touched the block";
  EXPECT_LE(run.gap, kTolerance);
  EXPECT_LE(run.error, 0.01 * run.peak);
}

// The same frames with a budget that no factorisation fits in (only the first iteration of each
// frame runs). A frame whose contact update on a kept factor the line search cut short has its
// redo on a fresh factor refused by the budget: it keeps the descent it found, ends at its cap,
// and the next frame starts with the factorisation. Only a frame whose iteration found no
// descent ends out of time, where it started: 1 of the 300 here. Kills the descent undone as
// well (R19: 10 frames out of time, 1.21% of the motion from converged dynamics against 1.04%).
TEST(Probe, BudgetedHapticFramesKeepACutContactUpdate) {
  const HapticSweep run = haptic_sweep(haptic_frames(1e-9));
  ASSERT_GT(run.contacts, 0) << "the probe never touched the block";
  EXPECT_LE(run.out_of_time, 2);
  EXPECT_LE(run.error, 0.02 * run.peak);
}

// Frames with a time budget solve their contact problem no further than the iteration needs: a
// share of the residual it starts from. Their contact solves take at most half the sweeps of the
// same frames without a budget, solved to the converged solve's tolerance (2,220 against 6,378),
// and still close their gaps to the contact tolerance and stay within 1% of converged dynamics
// (0.34% here, as without the budget). Kills the share left out (R20: the same sweeps).
TEST(Probe, BudgetedHapticFramesSolveTheirContactsAsFarAsTheIterationNeeds) {
  const HapticSweep budgeted = haptic_sweep(haptic_frames(1000));
  ASSERT_FALSE(HasFailure()) << "in the budgeted frames";
  HapticSweep unbudgeted;
  {
    SCOPED_TRACE("the same frames without a budget");
    unbudgeted = haptic_sweep(haptic_frames(std::numeric_limits<double>::infinity()));
  }
  ASSERT_GT(budgeted.contacts, 0) << "the probe never touched the block";
  EXPECT_LE(budgeted.sweeps, unbudgeted.sweeps / 2);
  EXPECT_LE(budgeted.gap, kTolerance);
  EXPECT_LE(budgeted.error, 0.01 * budgeted.peak);
}

}  // namespace
}  // namespace liver_sim
