// Full Newton with Eigen's SimplicialLDLT instead of CHOLMOD (a reference for the factor's
// cost): the tangent factorised at every iterate and solved directly.
#include <Eigen/SparseCholesky>
#include <chrono>

#include "update_strategy.h"

namespace liver_sim {
namespace {

class FullNewtonEigen final : public UpdateStrategy {
 public:
  using UpdateStrategy::UpdateStrategy;
  bool factorizes() const override { return false; }  // not with CHOLMOD
  bool current_tangent() const override { return true; }

  bool prepare(StepResult& result) override {
    const auto t0 = std::chrono::steady_clock::now();
    const SparsePattern& pattern = parts_.matrix.pattern();
    const Eigen::Map<const Eigen::SparseMatrix<double>> A(pattern.rows(), pattern.rows(), pattern.nonzeros(),
                                                          pattern.column_start().data(), pattern.row_index().data(),
                                                          parts_.matrix.values().data());
    if (!analyzed_) ldlt_.analyzePattern(A);
    analyzed_ = true;
    ldlt_.factorize(A);
    result.timing.factorization_ms += ms_since(t0);
    ++result.factorizations;
    return ldlt_.info() == Eigen::Success && !(ldlt_.vectorD().array() <= 0).any();
  }

  int solve(const NewtonIteration& it, Eigen::VectorXd& dx) override {
    dx = ldlt_.solve(it.r);
    return 0;
  }

 private:
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Upper> ldlt_;
  bool analyzed_ = false;
};

}  // namespace

std::unique_ptr<UpdateStrategy> make_full_newton_eigen(const StrategyParts& parts) {
  return std::make_unique<FullNewtonEigen>(parts);
}

}  // namespace liver_sim
