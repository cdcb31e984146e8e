// The one-shot registration (registration/one_shot.h) of a tracking session, ROS-free, on a
// thread of its own (BackgroundJob): a solve takes about a second, during which the frames go
// on with the model as it was. The session starts it with a cloud and the alignment in force
// and, at the start of a later frame, takes the result and hands it to its registration
// (SurfaceRegistration::adopt_one_shot). The solver has its own model of the same mesh and
// scene, so nothing is shared with the frames while it runs.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Geometry>
#include <memory>
#include <optional>
#include <string>

#include "liver_sim/registration/one_shot.h"
#include "liver_sim/runtime/background_job.h"
#include "liver_sim/session/inputs.h"

namespace liver_sim {

class OneShotWorker {
 public:
  // Throws std::invalid_argument for options or a scene the one-shot registration refuses.
  OneShotWorker(const TetMesh& mesh, const Scene& scene, const OneShotOptions& options);

  struct Result {
    Cloud cloud;                   // the cloud registered
    std::optional<OneShotResult> solved;  // none: refused
    std::string error;             // why refused
    double cpu_time = 0;           // s, the thread's
  };
  // Unless one is running or done and not taken (false): starts the solve of `cloud` from
  // `alignment` (the cloud's frame -> the model's) and the shape `reference` (the session's
  // model state: OneShotRegistration::set_reference).
  bool start(Cloud cloud, const Eigen::Isometry3d& alignment, const Eigen::VectorXd& reference);
  // A solve done (once).
  std::optional<Result> take();
  void cancel() { job_.cancel(); }        // the one running is not handed over
  bool running() const { return !job_.idle(); }
  std::string place(const std::vector<int>& cpus) { return job_.place(cpus); }

 private:
  void solve();

  OneShotRegistration one_shot_;
  Eigen::Isometry3d alignment_ = Eigen::Isometry3d::Identity();
  Eigen::VectorXd reference_;
  Result result_;
  BackgroundJob job_;  // last: destroyed first, waiting for a solve in progress
};

}  // namespace liver_sim
