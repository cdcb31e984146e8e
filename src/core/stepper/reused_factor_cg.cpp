// Conjugate gradients on the tangent at the iterate, preconditioned by the factor of an
// earlier one; the factor serves until it preconditions poorly.
#include "liver_sim/linalg/conjugate_gradient.h"
#include "update_strategy.h"

namespace liver_sim {
namespace {

class ReusedFactorCG final : public UpdateStrategy {
 public:
  using UpdateStrategy::UpdateStrategy;
  bool factorizes() const override { return !parts_.factor.valid(); }
  bool current_tangent() const override { return true; }

  int solve(const NewtonIteration& it, Eigen::VectorXd& dx) override {
    // The operators capture `this` only: a std::function keeps that without an allocation.
    const Gmres::Operator tangent = [this](const Eigen::VectorXd& v, Eigen::VectorXd& out) {
      parts_.matrix.multiply(v, out);
    };
    const Gmres::Operator preconditioner = [this](const Eigen::VectorXd& in, Eigen::VectorXd& out) {
      parts_.factor.solver().solve(in, out);
    };
    const int krylov = cg_.solve(tangent, preconditioner, it.r, dx, it.forcing, kMaxKrylov, it.deadline);
    judge_preconditioner(krylov, cg_.relative_residual(), it.forcing, cg_.out_of_time());
    return krylov;
  }

 private:
  ConjugateGradient cg_;
};

}  // namespace

std::unique_ptr<UpdateStrategy> make_reused_factor_cg(const StrategyParts& parts) {
  return std::make_unique<ReusedFactorCG>(parts);
}

}  // namespace liver_sim
