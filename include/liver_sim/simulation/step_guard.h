// The simulation loop's barrier (the node's), ROS-free: a step runs behind it, and whatever goes
// wrong in it, an exception of any kind (std::bad_alloc included) or a non-finite value left in
// the model, becomes a counted fault with its text while the model stays the one before the step
// (NewtonStepper rolls back a step that throws or finds a non-finite value; a non-finite state
// that got past it is undone here). The loop then goes on serving and publishing.
#pragma once

#include <cstdint>
#include <exception>
#include <string>

#include "liver_sim/simulation/liver_model.h"

namespace liver_sim {

class StepGuard {
 public:
  // Runs step() (a model step, or a registration frame that steps it) on `model`. Returns its
  // result, or, after a fault, a Diverged result whose message is "fault: " and the fault's text.
  template <typename Step>
  StepResult step(LiverModel& model, const Step& step) {
    inject(model);
    const long held_up = model.stepper().held_up_on_purpose();
    StepResult r;
    try {
      r = step();
    } catch (const std::exception& e) {
      r = fault(std::string("exception in the step: ") + e.what());
    } catch (...) {
      r = fault("exception of unknown type in the step");
    }
    if (!last_step_faulted_) r = checked(model, r);
    // However often the step solved (a registration frame may solve twice) and however it ended.
    if (model.stepper().held_up_on_purpose() != held_up)
      r.message += std::string(r.message.empty() ? "" : "; ") + kHeldUpText;
    return r;
  }

  // Counts a fault caught elsewhere in the loop (an input's application, publishing).
  void count(const std::string& text);

  uint64_t faults() const { return faults_; }  // since construction
  const std::string& last_fault() const { return last_fault_; }
  bool last_step_faulted() const { return last_step_faulted_; }

  // Test hook (the soak, ~test_fault_every): every n-th guarded step (0: never) meets an injected
  // fault (NewtonStepper::inject_fault), in turn an exception, an allocation failure, a NaN in the
  // update, a negative pivot and an update held up for 0.3 s.
  void set_test_fault_every(int n) { fault_every_ = n; }
  // Appended to the message of a step the injected delay held up (the soak finds those steps by it).
  static constexpr const char* kHeldUpText = "test hook: held up 0.3 s";

 private:
  void inject(LiverModel& model);
  StepResult fault(const std::string& text);
  // A step's result that left a non-finite value is undone and counted; so is a step rolled back
  // for a non-finite value.
  StepResult checked(LiverModel& model, const StepResult& r);

  uint64_t faults_ = 0;
  std::string last_fault_;
  bool last_step_faulted_ = false;
  int fault_every_ = 0;
  uint64_t guarded_steps_ = 0, injected_ = 0;
};

}  // namespace liver_sim
