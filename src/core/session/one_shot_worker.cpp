#include "liver_sim/session/one_shot_worker.h"

#include <stdexcept>

namespace liver_sim {

OneShotWorker::OneShotWorker(const TetMesh& mesh, const Scene& scene, const OneShotOptions& options)
    : one_shot_(mesh, scene, options), job_([this] { solve(); }) {}

bool OneShotWorker::start(Cloud cloud, const Eigen::Isometry3d& alignment, const Eigen::VectorXd& reference) {
  return job_.start([&] {
    result_ = Result();
    result_.cloud = std::move(cloud);
    alignment_ = alignment;
    reference_ = reference;
  });
}

std::optional<OneShotWorker::Result> OneShotWorker::take() {
  std::optional<Result> result;
  job_.take([&] { result = std::move(result_); });
  return result;
}

void OneShotWorker::solve() {
  const double started = thread_cpu_time();
  try {
    one_shot_.set_reference(reference_);
    result_.solved = one_shot_.solve(result_.cloud.points, result_.cloud.viewpoint, alignment_);
  } catch (const std::exception& e) {  // a cloud refused, out of memory, a factorisation failed
    result_.error = e.what();
  }
  result_.cpu_time = thread_cpu_time() - started;
}

}  // namespace liver_sim
