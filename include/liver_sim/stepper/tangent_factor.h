// The CHOLMOD factor of the Newton matrix (newton_matrix.h) that the update strategies solve or
// precondition with, ROS-free: whether it still serves, its refreshes (in the step, or with
// SolverOptions::background_refresh on a thread of its own while the old one serves), the
// length of the last factorisation (the time budget asks whether another fits) and what a
// rollback restores of it. Only the factor itself is not copied for a rollback (its size is the
// factor's): a rolled-back step that refactorised leaves it to be refactorised.
#pragma once

#include <chrono>
#include <memory>
#include <vector>

#include "liver_sim/linalg/background_factorization.h"
#include "liver_sim/linalg/cholmod_solver.h"
#include "liver_sim/linalg/sparse_pattern.h"
#include "liver_sim/stepper/step_result.h"

namespace liver_sim {

class NewtonMatrix;

class TangentFactor {
 public:
  using Clock = std::chrono::steady_clock;
  // Analyses the pattern (CHOLMOD), which must outlive the factor.
  explicit TangentFactor(const SparsePattern& pattern);

  CholmodSolver& solver() { return cholmod_; }
  // The factor preconditions the current constraint set and material.
  bool valid() const { return valid_; }
  // The factor no longer fits the model: the next iteration factorises in the step, and a
  // background factorisation in progress is not taken up.
  void drop();
  // The next iteration that uses the factor factorises it afresh in the step.
  void mark_stale() { valid_ = false; }
  // Background refresh: the factor serves, a fresh one is asked for.
  void want_refresh() { refresh_wanted_ = true; }

  // A factorisation of the matrix in the step (a background one would replace this newer
  // factor, which has not been judged yet: it is cancelled). Adds its time and count to result.
  // False when the matrix is not positive definite.
  bool factorize(const std::vector<double>& values, StepResult& result);
  // Whether a factorisation as long as the last one would end before the deadline.
  bool fits(Clock::time_point deadline) const { return Clock::now() + factorization_time_ <= deadline; }

  // SolverOptions::background_refresh turned on: the thread and its solver's analysis, once
  // (not in a step). Throws when there is no memory or no thread.
  void start_background();
  // Turned off: a refresh asked for and not yet taken up happens in the step, as without it.
  void stop_background();
  // At the start of an iteration: a finished background factor replaces the one in use; a
  // wanted one starts from the matrix assembled where the state was last evaluated, if the
  // thread is free.
  void refresh_in_background(NewtonMatrix& matrix, StepResult& result);

  // What a rolled-back step restores.
  struct State {
    bool valid = false, refresh_wanted = false;
    long factorizations = 0;      // factorisations since construction, when taken
    long background_starts = 0;   // background factorisations started, when taken
  };
  void save(State& s) const;
  void restore(const State& s);

 private:
  const SparsePattern& pattern_;
  CholmodSolver cholmod_;
  bool valid_ = false;
  bool refresh_wanted_ = false;
  long factorizations_ = 0;  // factors made in the step or taken up from the background
  std::unique_ptr<BackgroundFactorization> background_;  // while background_refresh was ever on
  long background_starts_ = 0;
  Clock::duration factorization_time_{};  // of the last factorisation in the step
};

}  // namespace liver_sim
