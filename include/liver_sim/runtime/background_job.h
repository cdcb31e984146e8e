// One job at a time on a thread of its own at a lower priority (lower_calling_thread_priority,
// worker_pool.h): the caller starts it and goes on, and takes the result when it is done. The
// job's data belong to the thread while it runs and to the caller otherwise, so neither locks
// them. ROS-free; what the job is belongs to its owner (uncertainty_worker.h,
// background_factorization.h), which keeps this object as its last member: it is destroyed
// first, waiting for a job in progress, while the data the job uses still exist.
#pragma once

#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace liver_sim {

class BackgroundJob {
 public:
  // `work` runs on the thread, once per start(), without the lock.
  explicit BackgroundJob(std::function<void()> work);
  ~BackgroundJob();
  BackgroundJob(const BackgroundJob&) = delete;
  BackgroundJob& operator=(const BackgroundJob&) = delete;

  // Unless a job is in progress or done and not taken (false, nothing run): `prepare` (it may
  // set the job's data; what it throws propagates, and no job starts), then the job starts.
  template <class Prepare>
  bool start(Prepare&& prepare) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (state_ != State::Idle) return false;
      prepare();
      cancelled_ = false;
      state_ = State::Running;
    }
    wake_.notify_all();
    return true;
  }
  // A job done and not cancelled: `hand_over` (it may take the job's data), and true.
  template <class HandOver>
  bool take(HandOver&& hand_over) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (state_ != State::Done) return false;
    state_ = State::Idle;
    hand_over();
    return true;
  }
  // The job in progress or done will not be handed over.
  void cancel();
  // No job in progress, none waiting to be taken.
  bool idle() const;
  // Runs the thread on these processors from now on (pin_thread: "" or why not). Unplaced it
  // runs where the thread that made it runs.
  std::string place(const std::vector<int>& cpus);

 private:
  void run();
  enum class State { Idle, Running, Done };
  std::function<void()> work_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  State state_ = State::Idle;
  bool cancelled_ = false;  // the one Running goes back to Idle when it ends
  bool stop_ = false;
  std::thread thread_;  // last: started once the rest is built
};

// Processor time of the calling thread (s): what a job cost, whatever else shares its processor.
double thread_cpu_time();

}  // namespace liver_sim
