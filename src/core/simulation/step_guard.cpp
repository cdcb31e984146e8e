#include "liver_sim/simulation/step_guard.h"

#include <iterator>

namespace liver_sim {

void StepGuard::count(const std::string& text) {
  ++faults_;
  last_fault_ = text;
}

void StepGuard::inject(LiverModel& model) {
  last_step_faulted_ = false;
  ++guarded_steps_;
  if (fault_every_ <= 0 || guarded_steps_ % fault_every_ != 0) return;
  using Fault = NewtonStepper::InjectedFault;
  static constexpr Fault kCycle[] = {Fault::Exception, Fault::OutOfMemory, Fault::NonFinite, Fault::NotPositiveDefinite,
                                     Fault::Slow};
  model.stepper().inject_fault(kCycle[injected_++ % std::size(kCycle)]);
}

static_assert(NewtonStepper::kInjectedDelay == std::chrono::milliseconds(300), "StepGuard::kHeldUpText tells 0.3 s");

StepResult StepGuard::fault(const std::string& text) {
  count(text);
  last_step_faulted_ = true;
  StepResult r;
  r.status = StepResult::Status::Diverged;
  r.message = "fault: " + text;
  return r;
}

StepResult StepGuard::checked(LiverModel& model, const StepResult& r) {
  if (!model.finite_state()) {
    if (model.undo_step()) return fault("non-finite state after the step, undone");
    model.reset();  // no state before the step to go back to: the rest shape is one that holds
    return fault("non-finite state after the step, reset to the rest shape");
  }
  if (r.status == StepResult::Status::Diverged && r.message.rfind("non-finite", 0) == 0) {
    count(r.message);
    last_step_faulted_ = true;
  }
  return r;
}

}  // namespace liver_sim
