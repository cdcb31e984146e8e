// Newton-Krylov: GMRES on the true Jacobian (directional differences of the residual),
// preconditioned by the factorised corotational tangent of an earlier iterate. The tangent
// alone misses the rotation derivative and the follower-load stiffness, which under suction on
// soft tissue are as large as the material stiffness and make a plain modified Newton crawl.
// With contacts, GMRES on the Jacobian with the contact rows (InstrumentContact::krylov_update).
// The factor serves until it preconditions poorly or the constraints change.
#include <chrono>

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
    if (parts_.contact.active()) return solve_with_contacts(it, dx);
    // Captures `this` only: a std::function keeps that without an allocation.
    const Gmres::Operator preconditioner = [this](const Eigen::VectorXd& in, Eigen::VectorXd& out) {
      parts_.factor.solver().solve(in, out);
    };
    // Without contacts the solve runs to its tolerance: cut at one iteration a frame, the
    // aspiration cube's follower load did not reach its equilibrium in 400 frames.
    const int krylov = gmres_.solve(it.jacobian, preconditioner, it.r, dx, it.forcing, kMaxKrylov);
    judge_preconditioner(krylov, gmres_.relative_residual(), it.forcing, false);
    return krylov;
  }

 private:
  int solve_with_contacts(const NewtonIteration& it, Eigen::VectorXd& dx) {
    const auto t0 = std::chrono::steady_clock::now();
    const InstrumentContact::Update update =
        parts_.contact.krylov_update(parts_.factor.solver(), it.jacobian, it.r, it.forcing, it.force_tolerance,
                                     it.deadline, dx);
    it.result.contact_sweeps += update.sweeps;
    it.result.timing.contact_ms += ms_since(t0);
    judge_preconditioner(update.krylov, update.relative_residual, it.forcing, update.out_of_time);
    return update.krylov;
  }

  Gmres gmres_;
};

}  // namespace

std::unique_ptr<UpdateStrategy> make_newton_krylov(const StrategyParts& parts) {
  return std::make_unique<NewtonKrylov>(parts);
}

}  // namespace liver_sim
