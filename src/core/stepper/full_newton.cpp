// Full Newton: the tangent assembled and factorised (CHOLMOD) at every iterate and solved
// directly; with contacts, the contact forces in the same solve (the direct contact update).
#include "update_strategy.h"

namespace liver_sim {
namespace {

class FullNewton final : public UpdateStrategy {
 public:
  using UpdateStrategy::UpdateStrategy;
  SolverOptions::Strategy with_contacts() const override { return SolverOptions::Strategy::FullNewton; }
  bool factorizes() const override { return true; }
  bool current_tangent() const override { return true; }
  int solve(const NewtonIteration& it, Eigen::VectorXd& dx) override { return direct_solve(it, dx); }
  bool scales_contact_forces() const override { return true; }
};

}  // namespace

std::unique_ptr<UpdateStrategy> make_full_newton(const StrategyParts& parts) {
  return std::make_unique<FullNewton>(parts);
}

}  // namespace liver_sim
