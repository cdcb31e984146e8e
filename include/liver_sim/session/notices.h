// What a tracking session refused and the events it tells, ROS-free and thread-safe: the
// callbacks' threads refuse inputs while the simulation thread applies others. A refusal is
// counted; a refusal or an event is told once, by the next status (take_fresh). Each is also
// handed to the sink given at construction (the node's log), on the thread that met it.
#pragma once

#include <cstdint>
#include <functional>
#include <mutex>
#include <string>

namespace liver_sim {

class Notices {
 public:
  enum class Kind { Refusal, Event };
  using Sink = std::function<void(Kind, const std::string&)>;
  explicit Notices(Sink sink = nullptr) : sink_(std::move(sink)) {}

  void refuse(const std::string& why);  // a refused input; the model is as it was
  void tell(const std::string& what);   // an event (not a refusal), e.g. a stale instrument

  uint32_t refused() const;             // since construction
  std::string last_refusal() const;
  // The text of the refusals and events since the last call (the last one of them), once, and
  // the refusals counted with it.
  std::string take_fresh(uint32_t* refused = nullptr);

 private:
  Sink sink_;
  mutable std::mutex mutex_;
  uint32_t refused_ = 0;
  std::string last_refusal_, fresh_;
};

}  // namespace liver_sim
