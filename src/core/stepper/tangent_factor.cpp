#include "liver_sim/stepper/tangent_factor.h"

#include "liver_sim/stepper/newton_matrix.h"

namespace liver_sim {

TangentFactor::TangentFactor(const SparsePattern& pattern) : pattern_(pattern) {
  cholmod_.analyze(pattern.rows(), pattern.column_start(), pattern.row_index());
}

void TangentFactor::drop() {
  valid_ = false;
  refresh_wanted_ = false;
  if (background_) background_->cancel();
}

bool TangentFactor::factorize(const std::vector<double>& values, StepResult& result) {
  const auto t0 = Clock::now();
  if (background_) background_->cancel();
  refresh_wanted_ = false;
  valid_ = cholmod_.factorize(values);
  factorization_time_ = Clock::now() - t0;
  ++factorizations_;
  result.timing.factorization_ms += std::chrono::duration<double, std::milli>(factorization_time_).count();
  ++result.factorizations;
  return valid_;
}

void TangentFactor::start_background() {
  if (background_) return;
  background_ = std::make_unique<BackgroundFactorization>(pattern_.rows(), pattern_.column_start(), pattern_.row_index());
}

void TangentFactor::stop_background() {
  if (refresh_wanted_ || (background_ && !background_->idle())) valid_ = false;
  refresh_wanted_ = false;
  if (background_) background_->cancel();
}

void TangentFactor::refresh_in_background(NewtonMatrix& matrix, StepResult& result) {
  if (const std::optional<bool> taken = background_->take(cholmod_)) {
    refresh_wanted_ = false;  // a new factor has not been judged yet
    if (*taken) {
      ++factorizations_;  // a rollback sees the new factor
      ++result.background_factorizations;
    } else {
      valid_ = false;  // not positive definite: the factorisation in the step meets it and rolls back
    }
  }
  if (valid_ && refresh_wanted_ && background_->idle()) {
    matrix.assemble(result.timing);  // where the residual was last evaluated: the iterate
    background_->start(matrix.values());
    ++background_starts_;
    refresh_wanted_ = false;
  }
}

void TangentFactor::save(State& s) const {
  s.valid = valid_;
  s.refresh_wanted = refresh_wanted_;
  s.factorizations = factorizations_;
  s.background_starts = background_starts_;
}

void TangentFactor::restore(const State& s) {
  // The factor is the one from before the step unless the step replaced it.
  valid_ = s.valid && factorizations_ == s.factorizations;
  // A background factorisation started in the step is of a state given up; one started before
  // it is of the state restored.
  refresh_wanted_ = s.refresh_wanted;
  if (background_ && background_starts_ != s.background_starts) background_->cancel();
}

}  // namespace liver_sim
