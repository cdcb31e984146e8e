#include "liver_sim/registration/uncertainty_worker.h"

#include <stdexcept>

namespace liver_sim {
namespace {

bool finite(const std::vector<TargetUncertainty::Covariance>& covariances) {
  for (const TargetUncertainty::Covariance& c : covariances)
    if (!c.total.allFinite()) return false;
  return true;
}

}  // namespace

UncertaintyWorker::UncertaintyWorker(std::unique_ptr<LiverModel> model, const UncertaintyOptions& options)
    : model_(std::move(model)), compliance_(*model_), uncertainty_(*model_, options), job_([this] { analyse(); }) {}

void UncertaintyWorker::set_capsule(const CapsuleOptions& capsule) {
  std::lock_guard<std::mutex> lock(capsule_mutex_);
  capsule_ = capsule;
}

bool UncertaintyWorker::start(const LiverModel& model, std::vector<SurfaceTarget> cloud_springs, uint64_t tag,
                              const SurfaceRegistration* registration) {
  // The thread is idle while the job is prepared: the model is the caller's to change.
  return job_.start([&] {
    {
      std::lock_guard<std::mutex> lock(capsule_mutex_);
      if (capsule_) {
        const CapsuleOptions capsule = *capsule_;
        capsule_.reset();  // tried once: a refused one would be refused at every start
        const std::string error = model_->set_capsule(capsule);
        if (!error.empty()) throw std::invalid_argument("the analysis's capsule: " + error);
      }
    }
    model_->set_stiffness_scale(model.stiffness_scale());
    model_->set_load_scale(model.load_scale());
    model_->set_surface_targets(model.surface_targets());
    model_->set_surface_loads(model.surface_loads());
    model_->set_positions(model.positions());
    compliance_.set_instrument_forces(model.contact().forces(model.positions()));
    result_ = Result();
    result_.tag = tag;
    result_.cloud_springs = std::move(cloud_springs);
    registration_ = registration;
    if (registration) hidden_loads_ = registration->hidden_loads();
  });
}

std::optional<UncertaintyWorker::Result> UncertaintyWorker::take() {
  std::optional<Result> result;
  job_.take([&] { result = std::move(result_); });
  return result;
}

void UncertaintyWorker::analyse() {
  const double started = thread_cpu_time();
  std::vector<TargetUncertainty::Covariance> covariances;
  std::string error;
  try {
    compliance_.factorize();
    covariances = uncertainty_.covariances(compliance_, result_.cloud_springs);
    if (!finite(covariances)) {
      covariances.clear();
      error = "a covariance is not finite";
    } else if (registration_) {
      result_.hidden_loads = registration_->hidden_load_fit(compliance_, result_.cloud_springs, hidden_loads_);
    }
  } catch (const std::exception& e) {  // not positive definite, out of memory, ...
    error = e.what();
  }
  result_.covariances = std::move(covariances);
  result_.error = std::move(error);
  result_.cpu_time = thread_cpu_time() - started;
}

}  // namespace liver_sim
