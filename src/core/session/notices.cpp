#include "liver_sim/session/notices.h"

namespace liver_sim {

void Notices::refuse(const std::string& why) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++refused_;
    last_refusal_ = fresh_ = why;
  }
  if (sink_) sink_(Kind::Refusal, why);
}

void Notices::tell(const std::string& what) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    fresh_ = what;
  }
  if (sink_) sink_(Kind::Event, what);
}

uint32_t Notices::refused() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return refused_;
}

std::string Notices::last_refusal() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return last_refusal_;
}

std::string Notices::take_fresh(uint32_t* refused) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (refused) *refused = refused_;
  std::string fresh;
  fresh.swap(fresh_);
  return fresh;
}

}  // namespace liver_sim
