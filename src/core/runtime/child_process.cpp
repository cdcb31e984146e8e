#include "liver_sim/runtime/child_process.h"

#include <poll.h>
#include <sys/prctl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

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

  ChildOutcome outcome;
  bool finished = false;
  std::string buffer, thrown;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    pollfd p{fds[0], POLLIN, 0};
    const int ready = left.count() > 0 ? poll(&p, 1, static_cast<int>(left.count())) : 0;
    if (ready < 0 && errno == EINTR) continue;
    if (ready == 0) {
      kill(pid, SIGKILL);
      outcome.status = ChildOutcome::Status::kTimedOut;
      break;
    }
    char chunk[65536];
    const ssize_t n = ready > 0 ? read(fds[0], chunk, sizeof chunk) : -1;
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;  // the child closed its end: it has ended
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
  close(fds[0]);
  int wait_status = 0;
  while (waitpid(pid, &wait_status, 0) < 0 && errno == EINTR) {
  }
  if (outcome.status == ChildOutcome::Status::kTimedOut) return outcome;
  if (finished && WIFEXITED(wait_status) && WEXITSTATUS(wait_status) == 0) {
    outcome.status = ChildOutcome::Status::kFinished;
    return outcome;
  }
  outcome.result.clear();
  outcome.reason = thrown.empty() ? how_it_ended(wait_status) : "threw: " + thrown;
  return outcome;
}

}  // namespace liver_sim
