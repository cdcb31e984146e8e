#include "liver_sim/uncertainty_worker.h"

#include <stdexcept>

#include "liver_sim/worker_pool.h"

namespace liver_sim {
namespace {

bool finite(const std::vector<TargetUncertainty::Covariance>& covariances) {
  for (const TargetUncertainty::Covariance& c : covariances)
    if (!c.total.allFinite()) return false;
  return true;
}

}  // namespace

UncertaintyWorker::UncertaintyWorker(std::unique_ptr<LiverModel> model, const UncertaintyOptions& options)
    : model_(std::move(model)), compliance_(*model_), uncertainty_(*model_, options), thread_([this] { run(); }) {}

UncertaintyWorker::~UncertaintyWorker() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void UncertaintyWorker::set_capsule(const CapsuleOptions& capsule) {
  std::lock_guard<std::mutex> lock(mutex_);
  capsule_ = capsule;
}

bool UncertaintyWorker::start(const LiverModel& model, std::vector<SurfaceTarget> cloud_springs, uint64_t tag) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (state_ != State::Idle) return false;
    // The thread waits while Idle: the model is the caller's to change.
    if (capsule_) {
      const CapsuleOptions capsule = *capsule_;
      capsule_.reset();  // tried once: a refused one would be refused at every start
      const std::string error = model_->set_capsule(capsule);
      if (!error.empty()) throw std::invalid_argument("the analysis's capsule: " + error);
    }
    model_->set_stiffness_scale(model.stiffness_scale());
    model_->set_surface_targets(model.surface_targets());
    model_->set_positions(model.positions());
    job_ = Result();
    job_.tag = tag;
    job_.cloud_springs = std::move(cloud_springs);
    state_ = State::Running;
  }
  wake_.notify_all();
  return true;
}

std::optional<UncertaintyWorker::Result> UncertaintyWorker::take() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (state_ != State::Done) return std::nullopt;
  state_ = State::Idle;
  return std::move(job_);
}

void UncertaintyWorker::run() {
  // Its processors stay the simulation's.
  lower_calling_thread_priority();
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stop_ || state_ == State::Running; });
    if (stop_) return;
    lock.unlock();
    // Only this thread touches the model and job_ while Running.
    std::vector<TargetUncertainty::Covariance> covariances;
    std::string error;
    try {
      compliance_.factorize();
      covariances = uncertainty_.covariances(compliance_, job_.cloud_springs);
      if (!finite(covariances)) {
        covariances.clear();
        error = "a covariance is not finite";
      }
    } catch (const std::exception& e) {  // not positive definite, out of memory, ...
      error = e.what();
    }
    lock.lock();
    job_.covariances = std::move(covariances);
    job_.error = std::move(error);
    state_ = State::Done;
  }
}

}  // namespace liver_sim
