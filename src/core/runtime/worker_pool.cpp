#include "liver_sim/runtime/worker_pool.h"

#include <malloc.h>
#include <omp.h>
#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <stdexcept>
#include <string>

namespace liver_sim {

WorkerPool::WorkerPool(int threads) {
  if (threads < 1 || threads > kMaxThreads)
    throw std::invalid_argument("threads must be in [1, " + std::to_string(kMaxThreads) + "] (got " +
                                std::to_string(threads) + ")");
  helpers_.reserve(threads - 1);
  for (int i = 1; i < threads; ++i) helpers_.emplace_back(&WorkerPool::help, this);
}

WorkerPool::~WorkerPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  for (std::thread& t : helpers_) t.join();
}

bool WorkerPool::claim(uint32_t generation, int chunks, int& chunk) {
  uint64_t next = next_.load(std::memory_order_acquire);
  while (static_cast<uint32_t>(next >> 32) == generation && static_cast<int>(next & 0xffffffffu) < chunks) {
    if (next_.compare_exchange_weak(next, next + 1, std::memory_order_acq_rel)) {
      chunk = static_cast<int>(next & 0xffffffffu);
      return true;
    }
  }
  return false;
}

void WorkerPool::run_shared(int chunks, Function function, const void* body) {
  uint32_t generation;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    function_ = function;
    body_ = body;
    chunks_ = chunks;
    generation = ++generation_;
    finished_.store(0, std::memory_order_relaxed);
    next_.store(static_cast<uint64_t>(generation) << 32, std::memory_order_release);
  }
  wake_.notify_all();
  int chunk, mine = 0;
  while (claim(generation, chunks, chunk)) {
    function(body, chunk);
    ++mine;
  }
  if (finished_.fetch_add(mine, std::memory_order_acq_rel) + mine == chunks) return;
  // Chunks that helpers are running: a short spin (they are usually about to finish), then sleep
  // until the last one says it is done.
  const auto spin_end = std::chrono::steady_clock::now() + std::chrono::microseconds(20);
  while (std::chrono::steady_clock::now() < spin_end)
    if (finished_.load(std::memory_order_acquire) == chunks) return;
  std::unique_lock<std::mutex> lock(mutex_);
  done_.wait(lock, [&] { return finished_.load(std::memory_order_acquire) == chunks; });
}

void WorkerPool::help() {
  uint32_t seen = 0;
  std::unique_lock<std::mutex> lock(mutex_);
  while (true) {
    wake_.wait(lock, [&] { return stop_ || generation_ != seen; });
    if (stop_) return;
    seen = generation_;
    const Function function = function_;
    const void* body = body_;
    const int chunks = chunks_;
    lock.unlock();
    int chunk, mine = 0;
    while (claim(seen, chunks, chunk)) {
      function(body, chunk);
      ++mine;
    }
    lock.lock();
    if (mine > 0) {
      helper_chunks_.fetch_add(mine, std::memory_order_relaxed);
      if (finished_.fetch_add(mine, std::memory_order_acq_rel) + mine == chunks) done_.notify_one();
    }
  }
}

std::vector<int> processors_of_calling_thread() {
  cpu_set_t set;
  CPU_ZERO(&set);
  pthread_getaffinity_np(pthread_self(), sizeof set, &set);
  std::vector<int> cpus;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu)
    if (CPU_ISSET(cpu, &set)) cpus.push_back(cpu);
  return cpus;
}

namespace {

std::string pin(pthread_t thread, const std::vector<int>& cpus) {
  if (cpus.empty()) return "no processor given";
  cpu_set_t set;
  CPU_ZERO(&set);
  for (int cpu : cpus) {
    if (cpu < 0 || cpu >= CPU_SETSIZE) return "processor " + std::to_string(cpu) + " does not exist";
    CPU_SET(cpu, &set);
  }
  const int error = pthread_setaffinity_np(thread, sizeof set, &set);
  return error == 0 ? "" : std::strerror(error);
}

}  // namespace

std::string pin_calling_thread(const std::vector<int>& cpus) { return pin(pthread_self(), cpus); }

std::string pin_thread(std::thread& thread, const std::vector<int>& cpus) { return pin(thread.native_handle(), cpus); }

std::string set_realtime_priority(int priority) {
  const int high = sched_get_priority_max(SCHED_FIFO);
  if (priority < 0 || priority > high)
    return "priority " + std::to_string(priority) + " is outside [0, " + std::to_string(high) + "]";
  sched_param p{};
  p.sched_priority = priority;
  const int error = pthread_setschedparam(pthread_self(), priority > 0 ? SCHED_FIFO : SCHED_OTHER, &p);
  return error == 0 ? "" : std::strerror(error);
}

void lower_calling_thread_priority() {
  constexpr int kNice = 10;
  set_realtime_priority(0);
  setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), kNice);
  omp_set_max_active_levels(0);
}

namespace {

// sched_setattr's argument as the kernel reads it (its first version, 48 bytes); glibc has no
// wrapper for the call.
struct SchedAttr {
  uint32_t size, policy;
  uint64_t flags;
  int32_t nice;
  uint32_t priority;
  uint64_t runtime, deadline, period;  // ns; for normal scheduling, runtime is the slice
};
static_assert(sizeof(SchedAttr) == 48, "sched_attr, first version");

}  // namespace

std::string set_slice_of_other_threads(double seconds) {
  if (!(seconds >= 1e-4 && seconds <= 0.1)) return "the slice must be in [1e-4, 0.1] s";
  const long self = syscall(SYS_gettid);
  std::error_code error;
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task", error)) {
    const long tid = std::strtol(task.path().filename().c_str(), nullptr, 10);
    if (tid == self) continue;
    errno = 0;
    const int nice = getpriority(PRIO_PROCESS, static_cast<id_t>(tid));
    if (errno != 0) continue;  // it ended meanwhile
    if (nice > 0) continue;  // a background job
    if (sched_getscheduler(static_cast<pid_t>(tid)) != SCHED_OTHER) continue;  // real-time or batch: kept  // a real-time or batch thread keeps its scheduling
    SchedAttr a{};
    a.size = sizeof a;
    a.policy = SCHED_OTHER;
    a.nice = nice;
    a.runtime = static_cast<uint64_t>(seconds * 1e9);
    if (syscall(SYS_sched_setattr, tid, &a, 0) != 0 && errno != ESRCH) return std::strerror(errno);
  }
  return error ? error.message() : "";
}

bool keep_freed_memory() {
  return mallopt(M_MMAP_THRESHOLD, 32 << 20) == 1 &&  // glibc's largest (HEAP_MAX_SIZE / 2, 64-bit)
         mallopt(M_TRIM_THRESHOLD, std::numeric_limits<int>::max()) == 1;
}

}  // namespace liver_sim
