// The time budget holds inside Newton-Krylov's solve with contacts: GMRES on the Jacobian with
// the contact rows (KrylovContactUpdate) stops at the step's deadline with its iterate so far,
// and the Newton loop judges that iteration as out of time. A probe pressed into a block with a
// budget every step exceeds at once: each step is one Newton iteration of one GMRES iteration,
// and step after step the model still reaches the equilibrium of the unlimited solve (the
// iterates are safe to continue from). Counts are asserted, never times.
// Mutations killed (tried): the deadline not passed to the contact update's GMRES (a step takes
// several GMRES iterations); a solve stopped at the deadline judged as a poor preconditioner
// (every step refactorises).
#include <gtest/gtest.h>

#include "contact/block_scenes.h"

namespace liver_sim {
namespace {

TEST(KrylovTimeBudget, AStepPastItsBudgetStopsGmresAfterOneIterationAndStillReachesTheEquilibrium) {
  const double L = 0.02, r = 0.004;
  Scene s = block_scene(3000, 0.45, 0);
  s.solver.strategy = SolverOptions::Strategy::NewtonKrylov;
  s.solver.max_iterations = 100;
  s.instruments.push_back(probe("probe", Eigen::Vector3d(L / 2, L / 2, L + r - 0.002), r));  // 2 mm into the top face

  LiverModel unlimited(make_box_mesh({L, L, L}, {6, 6, 6}), s);
  const StepResult reference = unlimited.step();
  ASSERT_TRUE(reference.converged()) << reference.message;
  ASSERT_GT(reference.linear_iterations, reference.iterations);  // GMRES needs more than one iteration per update

  s.solver.time_budget = 1e-9;
  LiverModel m(make_box_mesh({L, L, L}, {6, 6, 6}), s);
  StepResult step;
  step.status = StepResult::Status::NotConverged;
  int steps = 0, factorizations = 0;
  for (; steps < 300 && !step.converged(); ++steps) {
    step = m.step();
    ASSERT_NE(step.status, StepResult::Status::Diverged) << "step " << steps << ": " << step.message;
    if (step.converged()) break;
    ASSERT_TRUE(step.out_of_time) << "step " << steps << ": " << step.message;
    ASSERT_EQ(step.iterations, 1) << "step " << steps;
    if (m.contact().active()) {
      ASSERT_EQ(step.linear_iterations, 1) << "step " << steps;
    }
    if (steps > 0) factorizations += step.factorizations;
  }
  ASSERT_TRUE(step.converged()) << "after " << steps << " steps: " << step.message;
  EXPECT_GT(steps, 2);
  // The cut solves do not judge the factor: it serves the whole way.
  EXPECT_EQ(factorizations, 0);
  const Eigen::Vector3d force = m.instrument_reaction(0).force, expected = unlimited.instrument_reaction(0).force;
  EXPECT_LE((force - expected).norm(), 1e-5 * expected.norm()) << force.transpose() << " vs " << expected.transpose();
}

}  // namespace
}  // namespace liver_sim
