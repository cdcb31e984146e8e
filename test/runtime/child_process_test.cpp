#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "liver_sim/runtime/child_process.h"

using liver_sim::ChildOutcome;
using liver_sim::ChildProgress;
using liver_sim::run_in_child;

// The result comes back whole and the progress lines in their order, though the result is
// larger than a pipe holds (64 KiB) and comes after them; the work ran in another process.
// Kills: one read of the pipe (tried: the result cut at 64 KiB), progress lines dropped.
TEST(ChildProcess, TheResultAndTheProgressComeBackWhole) {
  const pid_t caller = getpid();
  std::vector<std::string> lines;
  const ChildOutcome o = run_in_child(
      [caller](const ChildProgress& progress) {
        progress("first");
        progress(getpid() == caller ? "same process" : "another process");
        std::string big(1 << 20, 'x');
        for (size_t i = 0; i < big.size(); i += 4096) big[i] = static_cast<char>('a' + i / 4096 % 26);
        return big;
      },
      60, [&](const std::string& line) { lines.push_back(line); });
  ASSERT_EQ(o.status, ChildOutcome::Status::kFinished) << o.reason;
  EXPECT_EQ(lines, (std::vector<std::string>{"first", "another process"}));
  ASSERT_EQ(o.result.size(), size_t{1} << 20);
  for (size_t i = 0; i < o.result.size(); i += 4096) ASSERT_EQ(o.result[i], static_cast<char>('a' + i / 4096 % 26));
}

// Work that never ends is stopped at its deadline and leaves no process behind; work that
// crashes or throws is reported as died, with how; a caller's callback that throws leaves no
// child either. Kills: the child not killed at the deadline (tried: the test hangs), a child that
// died taken as finished, the child left when the callback throws (tried each).
TEST(ChildProcess, AHangIsStoppedAndACrashOrThrowIsSaid) {
  pid_t hung = 0;
  const ChildOutcome slow = run_in_child(
      [](const ChildProgress& progress) -> std::string {
        progress(std::to_string(getpid()));
        for (;;) pause();
      },
      0.5, [&](const std::string& line) { hung = std::stoi(line); });
  EXPECT_EQ(slow.status, ChildOutcome::Status::kTimedOut);
  ASSERT_GT(hung, 0);
  EXPECT_EQ(kill(hung, 0), -1);  // reaped: no such process
  EXPECT_EQ(errno, ESRCH);

  // The caller's progress callback throws: the exception reaches the caller, the child is stopped.
  pid_t left = 0;
  EXPECT_THROW(run_in_child(
                   [](const ChildProgress& progress) -> std::string {
                     progress(std::to_string(getpid()));
                     for (;;) pause();
                   },
                   3600,
                   [&](const std::string& line) {
                     left = std::stoi(line);
                     throw std::runtime_error("the caller's own");
                   }),
               std::runtime_error);
  ASSERT_GT(left, 0);
  EXPECT_EQ(kill(left, 0), -1);

  const ChildOutcome crashed = run_in_child(
      [](const ChildProgress&) -> std::string {
        raise(SIGTERM);  // as a crash ends it, without a core file
        return "not reached";
      },
      60, nullptr);
  EXPECT_EQ(crashed.status, ChildOutcome::Status::kDied);
  EXPECT_EQ(crashed.reason, "killed by signal " + std::to_string(SIGTERM));
  EXPECT_TRUE(crashed.result.empty());

  const ChildOutcome threw = run_in_child(
      [](const ChildProgress&) -> std::string { throw std::runtime_error("no patches"); }, 60, nullptr);
  EXPECT_EQ(threw.status, ChildOutcome::Status::kDied);
  EXPECT_EQ(threw.reason, "threw: no patches");

  EXPECT_THROW(run_in_child([](const ChildProgress&) { return std::string(); }, 0, nullptr), std::invalid_argument);
  EXPECT_THROW(run_in_child([](const ChildProgress&) { return std::string(); }, std::nan(""), nullptr),
               std::invalid_argument);
}

// The child does not outlive its caller: a caller ended by its own watchdog takes its hung child
// with it. Here the caller is itself a child, stopped at its deadline. Kills: no death signal set
// in the child (tried: the grandchild still waits).
TEST(ChildProcess, TheChildEndsWithItsCaller) {
  pid_t grandchild = 0;
  const ChildOutcome caller = run_in_child(
      [](const ChildProgress& progress) -> std::string {
        run_in_child(
            [](const ChildProgress& inner) -> std::string {
              inner(std::to_string(getpid()));
              for (;;) pause();
            },
            3600, progress);
        return "not reached";
      },
      0.5, [&](const std::string& line) { grandchild = std::stoi(line); });
  EXPECT_EQ(caller.status, ChildOutcome::Status::kTimedOut);
  ASSERT_GT(grandchild, 0);
  // Gone, or a zombie waiting for whoever reaps orphans here; up to 10 s for the kernel to say so.
  auto ended = [&] {
    std::ifstream stat("/proc/" + std::to_string(grandchild) + "/stat");
    std::string pid, name, state;
    return !(stat >> pid >> name >> state) || state == "Z";
  };
  for (int i = 0; i < 100 && !ended(); ++i) usleep(100000);
  EXPECT_TRUE(ended());
  if (!ended()) kill(grandchild, SIGKILL);
}
