// Work run in a child process with a deadline: for third-party code that can loop without end or
// crash on rare inputs (gmsh, volume_mesher.h). A thread cannot be stopped; a process can, and
// its crash is not ours. The child is a fork of the caller: it sees the caller's data as they were
// and sends back what the work returns, and its progress lines as they come, through a pipe. Call
// it from a process whose other threads hold no lock the work needs (a tool's main thread).
#pragma once

#include <functional>
#include <string>

namespace liver_sim {

struct ChildOutcome {
  enum class Status { kFinished, kTimedOut, kDied };
  Status status = Status::kDied;
  std::string result;  // kFinished: what the work returned
  std::string reason;  // kDied: how ("killed by signal 11", "threw: ...", "exited with status 1")
};

using ChildProgress = std::function<void(const std::string&)>;

// Runs `work` in a child process; each line it passes to its argument reaches `progress` (when
// set) in the caller. Past `seconds` (> 0) the child is killed (kTimedOut). What the work throws
// ends the child (kDied, with what() in `reason`).
ChildOutcome run_in_child(const std::function<std::string(const ChildProgress&)>& work, double seconds,
                          const ChildProgress& progress);

}  // namespace liver_sim
