// The targets' uncertainty analysis (target_uncertainty.h) on a thread of its own, ROS-free: its
// factorisation and solves (about 90 ms of processor time on the phantom at a depth camera's
// density) then hold up no frame of the simulation. The caller hands over the registered state
// and takes the covariances when they are ready; meanwhile its frames go on.
//
// The thread works on a model of its own (the same mesh and scene as the caller's), brought to
// the state handed over: positions, the springs, the tissue's stiffness factor and the capsule,
// all that the static stiffness K + springs depends on; the load scale, the hidden loads (the
// unknown forces' scale is taken without them) and the instruments' forces (its model has no
// instruments: StateCompliance::set_instrument_forces), which the equilibrium it reads at
// depends on too. It runs at a lower priority (nice +10): where it shares a core with the
// simulation, the frames come first, and still it gets about a tenth of a core that other
// programs keep busy.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/runtime/background_job.h"
#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/registration/registration.h"
#include "liver_sim/registration/state_compliance.h"
#include "liver_sim/registration/target_uncertainty.h"

namespace liver_sim {

class UncertaintyWorker {
 public:
  // `model`: the worker's own, built from the caller's mesh and scene and not yet stepped, with
  // solver.threads 1 (helper threads would start at the caller's priority). Throws
  // std::invalid_argument for invalid options.
  UncertaintyWorker(std::unique_ptr<LiverModel> model, const UncertaintyOptions& options);

  // The capsule of the models analysed from the next start() on (the caller's changed).
  void set_capsule(const CapsuleOptions& capsule);

  // Starts the analysis of `model`'s current state. `cloud_springs`: the cloud's springs among
  // the model's (SurfaceRegistration::cloud_springs); `tag`: the caller's, returned with the
  // result. With `registration` (the caller's, registering `model`), the analysis also makes
  // its hidden loads' fit (SurfaceRegistration::hidden_load_fit, with its hidden loads of now),
  // for the caller to apply. Returns false, starting nothing, while an analysis runs or its
  // result awaits take(). Throws std::invalid_argument, starting nothing, when the model
  // refuses the capsule of set_capsule() (not tried again).
  bool start(const LiverModel& model, std::vector<SurfaceTarget> cloud_springs, uint64_t tag,
             const SurfaceRegistration* registration = nullptr);

  struct Result {
    uint64_t tag = 0;
    std::vector<TargetUncertainty::Covariance> covariances;  // of tracked_targets, in order; empty on error
    std::vector<SurfaceTarget> cloud_springs;                  // those handed to start()
    SurfaceRegistration::HiddenLoadFit hidden_loads;           // empty without a registration or when off
    std::string error;  // why there are no covariances (a stiffness not positive definite, ...)
    double cpu_time = 0;  // s, the processor time the analysis took on its thread
  };
  // The finished analysis, once; nothing while it runs or when none was started.
  std::optional<Result> take();

  // The factor of the analysis last taken, until the next start(): the registration's estimates
  // (candidate supports, the tissue's stiffness) solve with it.
  StateCompliance& compliance() { return compliance_; }

  // Its thread on these processors (BackgroundJob::place): "" or why not.
  std::string place(const std::vector<int>& cpus) { return job_.place(cpus); }

 private:
  void analyse();  // the job, on the thread

  std::unique_ptr<LiverModel> model_;
  StateCompliance compliance_;
  TargetUncertainty uncertainty_;
  std::mutex capsule_mutex_;
  std::optional<CapsuleOptions> capsule_;  // to apply at the next start()
  Result result_;
  const SurfaceRegistration* registration_ = nullptr;  // of the analysis in progress
  std::vector<Eigen::Vector3d> hidden_loads_;          // its hidden loads at start()
  BackgroundJob job_;  // last: destroyed first, waiting for an analysis in progress
};

}  // namespace liver_sim
