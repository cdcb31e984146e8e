// The worker pool runs every chunk once, on as many threads as it was given, and ends them.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <thread>
#include <vector>

#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/runtime/worker_pool.h"
#include "runtime/process_threads.h"

namespace liver_sim {
namespace {

// Seen to fail with run() returning before the helpers' chunks finish (the wait after the
// caller's own chunks removed), and with a claim that lets the counter pass the last chunk.
TEST(WorkerPool, RunsEveryChunkOnceBeforeReturning) {
  for (int threads : {1, 2, 3, 8}) {
    WorkerPool pool(threads);
    for (int chunks : {0, 1, 2, 7, 300}) {
      std::vector<std::atomic<int>> runs(chunks + 1);  // one past the end: no chunk may run there
      pool.run(chunks, [&](int c) {
        if (c % 50 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));  // some chunks outlast others
        ++runs[std::min(c, chunks)];
      });
      for (int c = 0; c <= chunks; ++c)
        ASSERT_EQ(runs[c].load(), c < chunks ? 1 : 0) << threads << " threads, chunk " << c << " of " << chunks;
    }
  }
}

// All threads of the pool inside one loop at the same time: each chunk waits until as many
// threads as the pool has have entered. A pool that ignored its thread count would leave the
// first chunk waiting alone: a 30 s limit turns that into a failure instead of a hang (it bounds
// the test, it measures nothing). Seen to fail with the helpers not started.
TEST(WorkerPool, HasAsManyThreadsAtWorkAsItWasGiven) {
  for (int threads : {2, 3, 4}) {
    WorkerPool pool(threads);
    std::atomic<int> inside{0}, saw_all{0};
    pool.run(threads, [&](int) {
      ++inside;
      const auto limit = std::chrono::steady_clock::now() + std::chrono::seconds(30);
      while (inside.load() < threads && std::chrono::steady_clock::now() < limit) std::this_thread::yield();
      if (inside.load() == threads) ++saw_all;
    });
    EXPECT_EQ(saw_all.load(), threads) << threads << " threads";
    EXPECT_EQ(pool.helper_chunks(), threads - 1);
  }
}

TEST(WorkerPool, StartsItsHelpersAndEndsThem) {
  const int before = process_threads();
  {
    WorkerPool pool(4);
    EXPECT_EQ(pool.threads(), 4);
    EXPECT_EQ(process_threads(), before + 3);
  }
  EXPECT_EQ(process_threads(), before);
  EXPECT_THROW(WorkerPool(0), std::invalid_argument);
  EXPECT_THROW(WorkerPool(WorkerPool::kMaxThreads + 1), std::invalid_argument);
}

}  // namespace
}  // namespace liver_sim
