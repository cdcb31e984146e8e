#include "liver_sim/session/registration_analysis.h"

#include <chrono>
#include <ctime>
#include <stdexcept>

namespace liver_sim {

RegistrationAnalysis::RegistrationAnalysis(LiverModel& model, const Scene& scene, Placement placement, double period)
    : model_(model), placement_(placement), period_(period) {
  if (!(period >= 0)) throw std::invalid_argument("the analysis period must be >= 0 s");
  if (placement == Placement::Background) {
    Scene own = scene;
    own.solver.threads = 1;  // see UncertaintyWorker
    // The worker is itself the background: its model factorises on the worker's thread, and a
    // refresh thread of its own would sit idle.
    own.solver.background_refresh = false;
    worker_ = std::make_unique<UncertaintyWorker>(std::make_unique<LiverModel>(load_scene_mesh(own), own),
                                                  scene.registration.uncertainty);
  } else {
    // The targets embedded at the model's state now (the caller's start).
    uncertainty_ = std::make_unique<TargetUncertainty>(model, scene.registration.uncertainty);
    compliance_ = std::make_unique<StateCompliance>(model);
  }
}

void RegistrationAnalysis::void_started() { ++generation_; }

void RegistrationAnalysis::reset() {
  covariances_.clear();
  due_ = false;
  ++generation_;
}

void RegistrationAnalysis::set_capsule(const CapsuleOptions& capsule) {
  if (worker_) worker_->set_capsule(capsule);  // in frame the model analysed is the session's own
}

RegistrationAnalysis::Outcome RegistrationAnalysis::start(const FrameTime& now, SurfaceRegistration& registration) {
  Outcome out;
  if (!due_ || now.wall < next_) return out;
  if (placement_ == Placement::Background) {
    try {
      if (!worker_->start(model_, registration.cloud_springs(), generation_, &registration)) return out;
    } catch (const std::exception& e) {  // out of memory copying the state, a capsule refused
      out.error = e.what();
      return out;
    }
    due_ = false;
    next_ = now.wall + period_;
    started_at_ = now.stamp;
    return out;
  }
  due_ = false;
  next_ = now.wall + period_;
  const auto wall_start = std::chrono::steady_clock::now();
  const std::clock_t cpu_start = std::clock();  // the process's: in frame, the helper threads' work counts
  const std::vector<SurfaceTarget> springs = registration.cloud_springs();
  std::vector<TargetUncertainty::Covariance> covariances;
  try {
    compliance_->factorize();
    if (want_covariances_) covariances = uncertainty_->covariances(*compliance_, springs);
  } catch (const std::exception& e) {  // not positive definite, out of memory
    out.error = e.what();
  }
  if (out.error.empty()) {
    out.adopted = true;
    if (want_covariances_) {
      covariances_ = std::move(covariances);
      stamp_ = now.stamp;
    }
    estimate(*compliance_, springs, nullptr, registration, out);
  }
  want_covariances_ = false;
  out.cpu_time = cpu_time_ = static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
  out.wall_time = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  return out;
}

RegistrationAnalysis::Outcome RegistrationAnalysis::adopt(SurfaceRegistration& registration) {
  Outcome out;
  if (!worker_) return out;
  std::optional<UncertaintyWorker::Result> result = worker_->take();
  if (!result || result->tag != generation_) return out;
  out.cpu_time = cpu_time_ = result->cpu_time;
  if (!result->error.empty()) {
    out.error = result->error;
    return out;
  }
  out.adopted = true;
  covariances_ = std::move(result->covariances);
  stamp_ = started_at_;
  estimate(worker_->compliance(), result->cloud_springs, &result->hidden_loads, registration, out);
  return out;
}

void RegistrationAnalysis::estimate(StateCompliance& compliance, const std::vector<SurfaceTarget>& springs,
                                    const SurfaceRegistration::HiddenLoadFit* fit, SurfaceRegistration& registration,
                                    Outcome& out) {
  try {
    out.support_held = registration.estimate_supports(compliance, springs);
    const double stiffness = model_.stiffness_scale();
    const std::vector<Eigen::Vector3d> loads = registration.hidden_loads();
    registration.estimate_tissue_stiffness(compliance, springs);  // both registration.*_tissue_stiffness_factor 1: off
    if (fit)
      registration.apply_hidden_loads(*fit);  // fitted on the worker's thread; empty when off
    else
      registration.estimate_hidden_loads(compliance, springs);
    out.model_changed =
        out.support_held >= 0 || model_.stiffness_scale() != stiffness || registration.hidden_loads() != loads;
  } catch (const std::runtime_error& e) {
    out.estimate_error = e.what();
  }
}

}  // namespace liver_sim
