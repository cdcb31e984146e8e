// A CHOLMOD factorisation on a thread of its own, at a lower priority, while the caller goes on
// solving with its old factor: modified Newton's refresh taken out of the real-time frame
// (SolverOptions::background_refresh, newton_stepper.h). On one core the factorisation then runs
// in the time the frames leave, instead of making a frame two or three frames long. ROS-free;
// knows nothing of the physics.
#pragma once

#include <condition_variable>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "liver_sim/cholmod_solver.h"

namespace liver_sim {

class BackgroundFactorization {
 public:
  // Analyses the n x n pattern (the arrays must outlive this object) and starts the thread.
  BackgroundFactorization(int n, const std::vector<int>& column_start, const std::vector<int>& row_index);
  ~BackgroundFactorization();  // waits for a factorisation in progress
  BackgroundFactorization(const BackgroundFactorization&) = delete;
  BackgroundFactorization& operator=(const BackgroundFactorization&) = delete;

  // Starts factorising a copy of `values` (laid out as the pattern) unless one is in progress or
  // finished and not taken: false then, nothing started.
  bool start(const std::vector<double>& values);
  // A finished factorisation handed to `solver` (analysed on the same pattern; its old factor
  // comes here): true. False when the matrix was not positive definite (solver unchanged);
  // nothing while none has finished.
  std::optional<bool> take(CholmodSolver& solver);
  // The factorisation in progress or finished will not be handed over: its matrix is no longer
  // the model's.
  void cancel();
  // None in progress, none waiting to be taken.
  bool idle() const;

 private:
  void run();
  enum class State { Idle, Running, Done };
  CholmodSolver solver_;
  std::vector<double> values_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  State state_ = State::Idle;
  bool cancelled_ = false;  // the one Running is dropped when it ends
  bool factored_ = false;   // Done: positive definite
  bool stop_ = false;
  std::thread thread_;  // last: started when the rest is ready
};

}  // namespace liver_sim
