// Threads for the model's loops: the calling thread and threads - 1 helper threads run the
// chunks of a loop, each chunk once. Made for a computer that other programs share (an OR's
// guidance computer; doc/performance.md#threads-on-a-shared-computer):
// - the caller never waits for a helper that has not started: chunks are claimed one at a time
//   from a counter, and the caller runs every chunk that no helper has claimed; it waits only
//   for chunks that a helper is running, so a helper the system keeps off the processor costs
//   at most one chunk's wait, never the loop;
// - helpers sleep between loops (a spinning helper takes the processor from whoever needs it);
// - which thread runs a chunk changes no result: a loop writes per chunk (or per element) and
//   its caller combines those in a fixed order.
// With one thread there are no helpers and run() is a plain loop. Knows nothing of the physics.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace liver_sim {

class WorkerPool {
 public:
  static constexpr int kMaxThreads = 64;

  // threads in [1, kMaxThreads]; throws std::invalid_argument otherwise. Starts threads - 1
  // helpers, which inherit the calling thread's processor affinity and scheduling policy.
  explicit WorkerPool(int threads = 1);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int threads() const { return static_cast<int>(helpers_.size()) + 1; }

  // Calls body(chunk) for every chunk in [0, chunks), on this thread and the helpers, and
  // returns when every call has returned. Allocates nothing. Not reentrant: body may not call
  // run() of the same pool.
  template <typename Body>
  void run(int chunks, const Body& body) {
    if (helpers_.empty() || chunks <= 1) {
      for (int c = 0; c < chunks; ++c) body(c);
      return;
    }
    run_shared(chunks, &call<Body>, &body);
  }

  // Chunks run by helpers since the pool started (the rest ran on the calling thread).
  long helper_chunks() const { return helper_chunks_.load(std::memory_order_relaxed); }

 private:
  using Function = void (*)(const void* body, int chunk);
  template <typename Body>
  static void call(const void* body, int chunk) {
    (*static_cast<const Body*>(body))(chunk);
  }
  void run_shared(int chunks, Function function, const void* body);
  // Claims the next chunk of loop `generation`; false when that loop has none left (or is over).
  bool claim(uint32_t generation, int chunks, int& chunk);
  void help();

  std::vector<std::thread> helpers_;
  std::mutex mutex_;
  std::condition_variable wake_;  // helpers: a loop started (or the pool stops)
  std::condition_variable done_;  // the caller: the last chunk finished
  // The current loop, written under mutex_ before its generation is published.
  Function function_ = nullptr;
  const void* body_ = nullptr;
  int chunks_ = 0;
  uint32_t generation_ = 0;
  bool stop_ = false;
  // (generation << 32) | next chunk: a helper that wakes after its loop ended claims nothing.
  std::atomic<uint64_t> next_{0};
  std::atomic<int> finished_{0};
  std::atomic<long> helper_chunks_{0};
};

// Scheduling of the calling thread, the one that steps the model. Called before the model is
// built, its pool's helpers inherit it. The setters return "" or why the system refused
// (nothing changed then).
// The processors the thread may run on (numbered from 0, as the kernel does).
std::vector<int> processors_of_calling_thread();
// Runs the thread only on these processors.
std::string pin_calling_thread(const std::vector<int>& cpus);
// The same for another thread of the process.
std::string pin_thread(std::thread& thread, const std::vector<int>& cpus);
// Real-time scheduling (SCHED_FIFO) at a priority in [1, 99]: the thread then runs whenever it is
// ready, ahead of every normally scheduled thread (a build, a viewer); needs CAP_SYS_NICE or an
// RLIMIT_RTPRIO at least that high. 0: normal scheduling (SCHED_OTHER).
std::string set_realtime_priority(int priority);
// A background thread: normal scheduling at nice +10 (CFS then gives it about a tenth of the
// share of a thread at 0 when both want the core; a real-time thread preempts it outright), and
// CHOLMOD's OpenMP regions on it (cholmod_solver.cpp). The nice value is per thread on Linux; a
// thread started by the simulation's would otherwise inherit its real-time scheduling.
void lower_calling_thread_priority();
// The scheduler's slice (Linux 6.12+, EEVDF; s, in [1e-4, 0.1]) of every thread of the process
// but the calling one and those at a lower priority (nice > 0: background jobs): a thread that
// asks for a short slice runs at once when it wakes on a busy core, ahead of threads with
// longer ones, its share of the processor unchanged. For the threads that only wake to pass a
// message on (callbacks, roscpp's network threads, a heartbeat). Earlier kernels keep their own
// slice. Returns "" when every such thread took it, else the first refusal.
std::string set_slice_of_other_threads(double seconds);
// Memory the process frees stays with it, for the next allocation to reuse: no block under
// 32 MiB is mapped for itself, and the heap is not given back to the system. Otherwise a
// block freed by one analysis or cloud and allocated again by the next is handed back and
// faulted in again, page by page. The resident size then stays at its high-water mark.
// Returns false when the allocator refused (the process keeps its defaults).
bool keep_freed_memory();

}  // namespace liver_sim
