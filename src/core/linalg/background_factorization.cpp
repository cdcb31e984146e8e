#include "liver_sim/linalg/background_factorization.h"

namespace liver_sim {

BackgroundFactorization::BackgroundFactorization(int n, const std::vector<int>& column_start,
                                                 const std::vector<int>& row_index)
    : job_([this] {
        factored_ = false;
        try {
          factored_ = solver_.factorize(values_);
        } catch (const std::exception&) {  // the caller's own factorisation will meet the cause
        }
      }) {
  solver_.analyze(n, column_start, row_index);  // the thread touches the solver only in a job
}

bool BackgroundFactorization::start(const std::vector<double>& values) {
  return job_.start([&] { values_ = values; });  // no allocation after the first: the pattern's size
}

std::optional<bool> BackgroundFactorization::take(CholmodSolver& solver) {
  bool factored = false;
  if (!job_.take([&] {
        factored = factored_;
        if (factored) solver.swap_factor(solver_);
      }))
    return std::nullopt;
  return factored;
}

}  // namespace liver_sim
