#include "liver_sim/background_factorization.h"

#include "liver_sim/worker_pool.h"

namespace liver_sim {

BackgroundFactorization::BackgroundFactorization(int n, const std::vector<int>& column_start,
                                                 const std::vector<int>& row_index)
    : thread_([this] { run(); }) {
  solver_.analyze(n, column_start, row_index);  // the thread touches the solver only while Running
}

BackgroundFactorization::~BackgroundFactorization() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

bool BackgroundFactorization::start(const std::vector<double>& values) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (state_ != State::Idle) return false;
    values_ = values;  // no allocation after the first: the pattern's size
    cancelled_ = false;
    state_ = State::Running;
  }
  wake_.notify_all();
  return true;
}

std::optional<bool> BackgroundFactorization::take(CholmodSolver& solver) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (state_ != State::Done) return std::nullopt;
  state_ = State::Idle;
  if (factored_) solver.swap_factor(solver_);
  return factored_;
}

void BackgroundFactorization::cancel() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (state_ == State::Running) cancelled_ = true;
  if (state_ == State::Done) state_ = State::Idle;
}

bool BackgroundFactorization::idle() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return state_ == State::Idle;
}

void BackgroundFactorization::run() {
  // Its processors stay the caller's (on one core, the frames come first).
  lower_calling_thread_priority();
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stop_ || state_ == State::Running; });
    if (stop_) return;
    lock.unlock();
    // Only this thread touches the solver and the values while Running.
    bool factored = false;
    try {
      factored = solver_.factorize(values_);
    } catch (const std::exception&) {  // the caller's own factorisation will meet the cause
    }
    lock.lock();
    factored_ = factored;
    state_ = cancelled_ ? State::Idle : State::Done;
  }
}

}  // namespace liver_sim
