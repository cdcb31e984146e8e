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

int UpdateStrategy::krylov_solve(const NewtonIteration& it, Eigen::VectorXd& dx, Gmres::Clock::time_point deadline) {
  if (!parts_.contact.active()) {
    // Captures `this` only: a std::function keeps that without an allocation.
    const Gmres::Operator preconditioner = [this](const Eigen::VectorXd& in, Eigen::VectorXd& out) {
      parts_.factor.solver().solve(in, out);
    };
    const int krylov = gmres_.solve(it.jacobian, preconditioner, it.r, dx, it.forcing, kMaxKrylov, deadline);
    krylov_residual_ = gmres_.relative_residual();
    krylov_out_of_time_ = gmres_.out_of_time();
    return krylov;
  }
  const auto t0 = std::chrono::steady_clock::now();
  const InstrumentContact::Update update = parts_.contact.krylov_update(parts_.factor.solver(), it.jacobian, it.r,
                                                                        it.forcing, it.force_tolerance, deadline, dx);
  it.result.contact_sweeps += update.sweeps;
  it.result.timing.contact_ms += ms_since(t0);
  krylov_residual_ = update.relative_residual;
  krylov_out_of_time_ = update.out_of_time;
  return update.krylov;
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
