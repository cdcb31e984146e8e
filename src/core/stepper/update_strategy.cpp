#include "update_strategy.h"

#include <chrono>

namespace liver_sim {

// Each defined in its strategy's file.
std::unique_ptr<UpdateStrategy> make_newton_krylov(const StrategyParts& parts);
std::unique_ptr<UpdateStrategy> make_full_newton(const StrategyParts& parts);
std::unique_ptr<UpdateStrategy> make_full_newton_eigen(const StrategyParts& parts);
std::unique_ptr<UpdateStrategy> make_reused_factor_cg(const StrategyParts& parts);
std::unique_ptr<UpdateStrategy> make_jacobi_cg(const StrategyParts& parts);
std::unique_ptr<UpdateStrategy> make_modified_newton(const StrategyParts& parts);

std::unique_ptr<UpdateStrategy> make_update_strategy(SolverOptions::Strategy strategy, const StrategyParts& parts) {
  using S = SolverOptions::Strategy;
  switch (strategy) {
    case S::NewtonKrylov: return make_newton_krylov(parts);
    case S::FullNewton: return make_full_newton(parts);
    case S::FullNewtonEigen: return make_full_newton_eigen(parts);
    case S::ReusedFactorCG: return make_reused_factor_cg(parts);
    case S::CG: return make_jacobi_cg(parts);
    case S::ModifiedNewton: return make_modified_newton(parts);
  }
  return make_newton_krylov(parts);
}

int UpdateStrategy::direct_solve(const NewtonIteration& it, Eigen::VectorXd& dx) {
  InstrumentContact& contact = parts_.contact;
  if (!contact.active()) {
    parts_.factor.solver().solve(it.r, dx);
    return 0;
  }
  const auto t0 = std::chrono::steady_clock::now();
  it.result.contact_sweeps += contact.direct_update(parts_.factor.solver(), it.r, it.force_tolerance, dx).sweeps;
  it.result.timing.contact_ms += ms_since(t0);
  return 0;
}

void UpdateStrategy::begin_iteration(StepResult& result) {
  if (parts_.solver.background_refresh && parts_.factor.valid()) parts_.factor.refresh_in_background(parts_.matrix, result);
}

void UpdateStrategy::judge_preconditioner(int iterations, double relative_residual, double forcing,
                                          bool out_of_time) {
  if (iterations > kRefactorAfter || (!out_of_time && relative_residual > forcing)) refresh();
}

void UpdateStrategy::refresh() {
  if (parts_.solver.background_refresh)
    parts_.factor.want_refresh();
  else
    parts_.factor.mark_stale();
}

}  // namespace liver_sim
