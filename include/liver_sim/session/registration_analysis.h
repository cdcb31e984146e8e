// The registration's analyses in a tracking session, ROS-free: after a registered cloud, at most
// once a period, one factorisation of the registered state gives the targets' covariances
// (target_uncertainty.h) and the estimates the clouds call for (registration.h: candidate
// supports, the tissue's stiffness, hidden loads), which the model takes from its next step.
// Two placements:
//   Background  on the UncertaintyWorker's thread and model; the result is adopted at the start
//               of a later frame, the frames going on meanwhile (the node).
//   InFrame     in the frame that registered the cloud, on the session's own model, adopted at
//               once: deterministic (benchmarks, tests). The covariances cost more than the
//               rest; in frame they are made only in a frame that asks for them.
// An analysis started before a reset or a capsule change describes a model that is gone: its
// result is dropped.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "liver_sim/registration/registration.h"
#include "liver_sim/registration/state_compliance.h"
#include "liver_sim/registration/target_uncertainty.h"
#include "liver_sim/registration/uncertainty_worker.h"
#include "liver_sim/session/inputs.h"

namespace liver_sim {

class RegistrationAnalysis {
 public:
  enum class Placement { Background, InFrame };
  // What an analysis did in a frame.
  struct Outcome {
    bool adopted = false;        // new covariances (or, in frame without them, new estimates)
    bool model_changed = false;  // a support held, the tissue's stiffness, the hidden loads: the model must step
    int support_held = -1;       // the candidate support newly held, or -1
    std::string error;           // why there are no covariances (a failed analysis, one that could not start)
    std::string estimate_error;  // why there are no estimates
    double cpu_time = 0;         // s of processor time the analysis took (the worker's thread's; in frame, the process's)
    double wall_time = 0;        // s, in frame only
  };

  // `model`: the session's; `scene`: the one it was built from (the background's own model is
  // built from it). Throws std::invalid_argument for invalid options.
  RegistrationAnalysis(LiverModel& model, const Scene& scene, Placement placement, double period);

  void due() { due_ = true; }              // a cloud was registered
  bool is_due() const { return due_; }
  void void_started();                     // a capsule change: an analysis running is void
  void reset();                            // a reset: nothing due, no covariances, a running one void
  void set_capsule(const CapsuleOptions& capsule);  // of the models analysed from the next start on
  void want_covariances() { want_covariances_ = true; }  // in frame: the next analysis makes them

  // Simulation thread, after a step that kept its state: starts an analysis when one is due and
  // the period since the last start has passed; in frame, runs it and adopts it.
  Outcome start(const FrameTime& now, SurfaceRegistration& registration);
  // Simulation thread, at the start of a frame: a finished background analysis adopted.
  Outcome adopt(SurfaceRegistration& registration);

  // Of the targets (tracked_targets), at the last adopted analysis; empty before one.
  const std::vector<TargetUncertainty::Covariance>& covariances() const { return covariances_; }
  Stamp stamp() const { return stamp_; }  // the stamp of the state they describe
  double cpu_time() const { return cpu_time_; }  // s, of the last analysis adopted (or failed)

 private:
  // The estimates from a factor of the registered state, with the cloud's springs it was made
  // with; `fit`: the hidden loads' fit made on the worker (none: made here).
  void estimate(StateCompliance& compliance, const std::vector<SurfaceTarget>& springs,
                const SurfaceRegistration::HiddenLoadFit* fit, SurfaceRegistration& registration, Outcome& out);

  LiverModel& model_;
  Placement placement_;
  double period_;  // s
  std::unique_ptr<UncertaintyWorker> worker_;  // background
  std::unique_ptr<StateCompliance> compliance_;     // in frame
  std::unique_ptr<TargetUncertainty> uncertainty_;  // in frame
  bool due_ = false;
  bool want_covariances_ = false;
  double next_ = 0;        // wall clock (s): the earliest next start
  Stamp started_at_ = 0;   // the state the running analysis describes
  Stamp stamp_ = 0;        // the state covariances_ describe
  double cpu_time_ = 0;
  uint64_t generation_ = 0;
  std::vector<TargetUncertainty::Covariance> covariances_;
};

}  // namespace liver_sim
