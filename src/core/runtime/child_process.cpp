#include "liver_sim/runtime/child_process.h"

#include <poll.h>
#include <sys/prctl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <stdexcept>

namespace liver_sim {
namespace {

// A record on the pipe: its kind, its length (8 bytes), its bytes.
constexpr char kProgress = 'P', kResult = 'R', kThrew = 'X';

bool write_all(int fd, const char* data, size_t size) {
  while (size > 0) {
    const ssize_t n = write(fd, data, size);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    data += n;
    size -= static_cast<size_t>(n);
  }
  return true;
}

bool send(int fd, char kind, const std::string& bytes) {
  const std::uint64_t size = bytes.size();
  char head[1 + sizeof size];
  head[0] = kind;
  std::memcpy(head + 1, &size, sizeof size);
  return write_all(fd, head, sizeof head) && write_all(fd, bytes.data(), bytes.size());
}

[[noreturn]] void child(int fd, const std::function<std::string(const ChildProgress&)>& work) {
  int status = 0;
  try {
    const std::string result = work([fd](const std::string& line) { send(fd, kProgress, line); });
    status = send(fd, kResult, result) ? 0 : 1;
  } catch (const std::exception& e) {
    send(fd, kThrew, e.what());
    status = 1;
  } catch (...) {
    send(fd, kThrew, "an exception that is not a std::exception");
    status = 1;
  }
  close(fd);
  _exit(status);  // not exit(): the caller's atexit handlers and buffers are the caller's
}

std::string how_it_ended(int wait_status) {
  if (WIFSIGNALED(wait_status)) return "killed by signal " + std::to_string(WTERMSIG(wait_status));
  return "exited with status " + std::to_string(WEXITSTATUS(wait_status));
}

}  // namespace

ChildOutcome run_in_child(const std::function<std::string(const ChildProgress&)>& work, double seconds,
                          const ChildProgress& progress) {
  if (!(seconds > 0) || !std::isfinite(seconds)) throw std::invalid_argument("run_in_child: seconds must be finite and > 0");
  const pid_t caller = getpid();
  int fds[2];
  if (pipe(fds) != 0) throw std::runtime_error(std::string("run_in_child: pipe: ") + std::strerror(errno));
  const pid_t pid = fork();
  if (pid < 0) {
    close(fds[0]);
    close(fds[1]);
    throw std::runtime_error(std::string("run_in_child: fork: ") + std::strerror(errno));
  }
  if (pid == 0) {
    // The child ends with the caller (a caller's own watchdog that ends it, a crash): a loop
    // without end must not outlive it.
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != caller) _exit(1);  // the caller ended before the line above
    close(fds[0]);
    child(fds[1], work);
  }
  close(fds[1]);

  // However this function ends (a progress callback that throws included), the child is
  // reaped, and stopped first unless it has ended.
  struct Child {
    pid_t pid;
    int fd;
    bool ended = false;   // it has sent its last record or closed its end of the pipe
    bool reaped = false;  // done with it
    bool waited = false;  // and its status is known
    int status = 0;
    void reap() {
      if (reaped) return;
      reaped = true;
      close(fd);
      if (!ended) kill(pid, SIGKILL);
      pid_t r;
      while ((r = waitpid(pid, &status, 0)) < 0 && errno == EINTR) {
      }
      waited = r == pid;
    }
    ~Child() { reap(); }
  } child_process{pid, fds[0]};

  ChildOutcome outcome;
  bool finished = false, timed_out = false;
  std::string buffer, thrown;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    pollfd p{fds[0], POLLIN, 0};
    // What is in the pipe is read even past the deadline: a result that came in time is not
    // thrown away because this process was slow to look.
    const int ready = poll(&p, 1, static_cast<int>(std::max<std::int64_t>(left.count(), 0)));
    if (ready < 0 && errno == EINTR) continue;
    if (ready < 0) break;  // an error: the child is stopped
    if (ready == 0) {
      timed_out = !finished;  // with its result in, it is only ending
      break;
    }
    char chunk[65536];
    const ssize_t n = read(fds[0], chunk, sizeof chunk);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      child_process.ended = n == 0;
      break;
    }
    buffer.append(chunk, static_cast<size_t>(n));
    // Whole records off the front.
    std::uint64_t size = 0;
    while (buffer.size() >= 1 + sizeof size) {
      std::memcpy(&size, buffer.data() + 1, sizeof size);
      if (buffer.size() < 1 + sizeof size + size) break;
      const char kind = buffer[0];
      std::string bytes = buffer.substr(1 + sizeof size, size);
      buffer.erase(0, 1 + sizeof size + size);
      if (kind == kProgress && progress) progress(bytes);
      if (kind == kResult) outcome.result = std::move(bytes), finished = true;
      if (kind == kThrew) thrown = std::move(bytes);
    }
  }
  child_process.ended |= finished;
  child_process.reap();
  if (timed_out) {
    outcome.status = ChildOutcome::Status::kTimedOut;
    outcome.result.clear();
    return outcome;
  }
  const int status = child_process.status;
  if (finished && child_process.waited && WIFEXITED(status) && WEXITSTATUS(status) == 0) {
    outcome.status = ChildOutcome::Status::kFinished;
    return outcome;
  }
  outcome.result.clear();
  outcome.reason = !thrown.empty()          ? "threw: " + thrown
                   : child_process.waited ? how_it_ended(status)
                                          : "its end unknown (not waitable: SIGCHLD ignored?)";
  return outcome;
}

}  // namespace liver_sim
