// Where background work runs and what wakes the simulation thread, ROS-free. A background job
// placed on a processor runs there (the node puts the factor refreshes and the analyses on the
// processors the simulation leaves); an input wakes a wait at once and a taken input does not
// wake the next. Mutations killed (tried): place() pinning the calling thread instead of the
// job's (the job then runs on all processors); take() not clearing the input (the second wait
// returns true).
#include <gtest/gtest.h>

#include <chrono>
#include <thread>
#include <vector>

#include "liver_sim/runtime/background_job.h"
#include "liver_sim/runtime/input_signal.h"
#include "liver_sim/runtime/worker_pool.h"

namespace liver_sim {
namespace {

TEST(BackgroundJob, APlacedJobRunsOnTheProcessorsItWasGiven) {
  const std::vector<int> mine = processors_of_calling_thread();
  ASSERT_FALSE(mine.empty());
  std::vector<int> seen;
  BackgroundJob job([&] { seen = processors_of_calling_thread(); });
  const std::vector<int> one{mine.back()};
  ASSERT_EQ(job.place(one), "");
  ASSERT_TRUE(job.start([] {}));
  while (!job.take([] {})) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_EQ(seen, one);
  EXPECT_EQ(processors_of_calling_thread(), mine) << "the caller stays where it was";
  EXPECT_NE(job.place({-1}), "") << "a processor that does not exist is refused";
}

TEST(InputSignal, AnInputWakesTheWaitAndATakenOneDoesNot) {
  using Clock = InputSignal::Clock;
  InputSignal signal;
  EXPECT_FALSE(signal.wait_until(Clock::now())) << "nothing came";
  std::thread sender([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    signal.notify();
  });
  EXPECT_TRUE(signal.wait_until(Clock::now() + std::chrono::hours(1))) << "woken by the input, not the deadline";
  sender.join();
  EXPECT_TRUE(signal.wait_until(Clock::now())) << "still there until taken";
  signal.take();
  EXPECT_FALSE(signal.wait_until(Clock::now() + std::chrono::milliseconds(1)));
}

}  // namespace
}  // namespace liver_sim
