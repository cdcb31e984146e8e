#include "liver_sim/runtime/background_job.h"

#include <ctime>

#include "liver_sim/runtime/worker_pool.h"

namespace liver_sim {

BackgroundJob::BackgroundJob(std::function<void()> work) : work_(std::move(work)), thread_([this] { run(); }) {}

BackgroundJob::~BackgroundJob() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void BackgroundJob::cancel() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (state_ == State::Running) cancelled_ = true;
  if (state_ == State::Done) state_ = State::Idle;
}

bool BackgroundJob::idle() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return state_ == State::Idle;
}

std::string BackgroundJob::place(const std::vector<int>& cpus) { return pin_thread(thread_, cpus); }

void BackgroundJob::run() {
  // Unless placed, its processors stay the caller's: on a shared core the caller's frames come
  // first.
  lower_calling_thread_priority();
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stop_ || state_ == State::Running; });
    if (stop_) return;
    lock.unlock();
    work_();  // must not throw: the owner's work catches what it can meet
    lock.lock();
    state_ = cancelled_ ? State::Idle : State::Done;
  }
}

double thread_cpu_time() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

}  // namespace liver_sim
