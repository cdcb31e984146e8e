// Newton-Krylov: GMRES on the true Jacobian (directional differences of the residual),
// preconditioned by the factorised corotational tangent of an earlier iterate. The tangent
// alone misses the rotation derivative and the follower-load stiffness, which under suction on
// soft tissue are as large as the material stiffness and make a plain modified Newton crawl.
// With contacts, GMRES on the Jacobian with the contact rows (InstrumentContact::krylov_update).
// The factor serves until it preconditions poorly or the constraints change.
#include "update_strategy.h"

namespace liver_sim {
namespace {

class NewtonKrylov final : public UpdateStrategy {
 public:
  using UpdateStrategy::UpdateStrategy;
  SolverOptions::Strategy with_contacts() const override { return SolverOptions::Strategy::NewtonKrylov; }
  bool factorizes() const override { return !parts_.factor.valid(); }
  bool current_tangent() const override { return false; }

  int solve(const NewtonIteration& it, Eigen::VectorXd& dx) override {
    // Without contacts the solve runs to its tolerance: cut at one iteration a frame, the
    // aspiration cube's follower load did not reach its equilibrium in 400 frames.
    const bool bounded = parts_.contact.active();
    const int krylov = krylov_solve(it, dx, bounded ? it.deadline : Gmres::Clock::time_point::max());
    judge_preconditioner(krylov, krylov_residual_, it.forcing, bounded && krylov_out_of_time_);
    return krylov;
  }
};

}  // namespace

std::unique_ptr<UpdateStrategy> make_newton_krylov(const StrategyParts& parts) {
  return std::make_unique<NewtonKrylov>(parts);
}

}  // namespace liver_sim
