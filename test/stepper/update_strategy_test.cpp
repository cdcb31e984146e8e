// Every update strategy (src/core/stepper/update_strategy.h) reaches the same contact equilibrium:
// a probe pressed into a block, stepped with each SolverOptions::Strategy. Modified and full
// Newton carry the contact forces in their own solve (the direct contact update); the others hand
// their iterations with contacts to Newton-Krylov (the Krylov update on the true Jacobian). All
// must agree, and the probe's reaction must balance the supports' (a sum over the fixed DOFs,
// computed apart from the contact). Mutation killed (tried): conjugate gradients keeping its
// iterations with contacts (its solve knows no contact force: the probe sinks in, the step does
// not converge).
#include <gtest/gtest.h>

#include "contact/block_scenes.h"

namespace liver_sim {
namespace {

TEST(UpdateStrategy, EveryStrategyReachesTheSameContactEquilibrium) {
  const double L = 0.02, r = 0.004;
  Scene s = block_scene(3000, 0.45, 0);
  s.solver.max_iterations = 400;  // the strategies without the rotation terms converge linearly
  const InstrumentOptions pressing = probe("probe", Eigen::Vector3d(L / 2, L / 2, L + r - 0.002), r);  // 2 mm into the top face

  Eigen::Vector3d reference = Eigen::Vector3d::Zero();
  for (const char* word : {"full_newton", "modified_newton", "newton_krylov", "full_newton_eigen", "reused_factor_cg", "cg"}) {
    s.solver.strategy = *parse_strategy(word);
    LiverModel m(make_box_mesh({L, L, L}, {6, 6, 6}), s);
    const int k = m.add_instrument(pressing);
    const StepResult result = m.step();
    ASSERT_TRUE(result.converged()) << word << ": " << result.message;
    const Eigen::Vector3d reaction = m.instrument_reaction(k).force;
    EXPECT_GT(reaction.z(), 0.0) << word;
    const Eigen::Vector3d support = total(m.stepper().support_forces());
    EXPECT_LE((support - reaction).norm(), 1e-6 * reaction.norm()) << word;
    if (reference.isZero()) reference = reaction;
    EXPECT_LE((reaction - reference).norm(), 1e-5 * reference.norm()) << word << ": " << reaction.transpose();
  }
}

}  // namespace
}  // namespace liver_sim
