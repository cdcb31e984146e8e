// A CHOLMOD factorisation on a thread of its own, at a lower priority, while the caller goes on
// solving with its old factor: modified Newton's refresh taken out of the real-time frame
// (SolverOptions::background_refresh, newton_stepper.h). On one core the factorisation then runs
// in the time the frames leave, instead of making a frame two or three frames long. ROS-free;
// knows nothing of the physics.
#pragma once

#include <optional>
#include <vector>

#include "liver_sim/runtime/background_job.h"
#include "liver_sim/linalg/cholmod_solver.h"

namespace liver_sim {

class BackgroundFactorization {
 public:
  // Analyses the n x n pattern (the arrays must outlive this object) and starts the thread.
  // Destroying it waits for a factorisation in progress.
  BackgroundFactorization(int n, const std::vector<int>& column_start, const std::vector<int>& row_index);

  // Starts factorising a copy of `values` (laid out as the pattern) unless one is in progress or
  // finished and not taken: false then, nothing started.
  bool start(const std::vector<double>& values);
  // A finished factorisation handed to `solver` (analysed on the same pattern; its old factor
  // comes here): true. False when the matrix was not positive definite (solver unchanged);
  // nothing while none has finished.
  std::optional<bool> take(CholmodSolver& solver);
  // The factorisation in progress or finished will not be handed over: its matrix is no longer
  // the model's.
  void cancel() { job_.cancel(); }
  // None in progress, none waiting to be taken.
  bool idle() const { return job_.idle(); }
  // Its thread on these processors (BackgroundJob::place).
  std::string place(const std::vector<int>& cpus) { return job_.place(cpus); }

 private:
  CholmodSolver solver_;
  std::vector<double> values_;
  bool factored_ = false;  // the last job's matrix was positive definite
  BackgroundJob job_;      // last: destroyed first, waiting for a job in progress
};

}  // namespace liver_sim
