// One cloud registered in one shot: the one-shot registration (registration/one_shot.h) handed
// over to the tracker (SurfaceRegistration::register_one_shot, the call a tracking session makes
// for its first cloud), then the targets read from the tracked model. Shared by the register and
// register_insilico tools. The node's TrackingSession (session/tracking_session.h) makes the
// same hand-over (adopt_one_shot) with the solve on a thread of its own (one_shot_worker.h).
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/registration/one_shot.h"
#include "liver_sim/registration/registration.h"
#include "liver_sim/scene/scene.h"
#include "liver_sim/simulation/liver_model.h"

namespace liver_sim {

// Sets the one-shot option named by `assignment` ("KEY=VALUE", SI units; the fields of
// OneShotOptions). Throws std::invalid_argument for an unknown key or a value that is not a
// number (whole for the counts); the bounds are validate()'s.
void set_one_shot_option(OneShotOptions& options, const std::string& assignment);

class OneShotSession {
 public:
  // The scene's model, its registration and a one-shot solver of the same mesh. Throws
  // std::invalid_argument (or SceneError, MeshError) for what the model, the registration or the
  // options refuse.
  OneShotSession(const Scene& scene, const OneShotOptions& options);

  // Points of the pre-operative model (its rest shape, model frame, m) followed from then on.
  void set_targets(const std::vector<Eigen::Vector3d>& rest_positions);

  struct Result {
    std::vector<Eigen::Vector3d> positions;  // m, the cloud's frame
    std::vector<OneShotRegistration::PointUncertainty> uncertainty;  // the cloud's frame
    SurfaceRegistration::OneShotReport report;
  };
  // Registers the model to the cloud (its own frame, m; `viewpoint` the sensor's origin there
  // when known) from the rest shape. Throws std::invalid_argument for a cloud the registration
  // refuses.
  Result register_cloud(const pcl::PointCloud<pcl::PointXYZ>& cloud,
                        const std::optional<Eigen::Vector3d>& viewpoint = std::nullopt);

  LiverModel& model() { return *model_; }

 private:
  std::unique_ptr<LiverModel> model_;
  std::unique_ptr<SurfaceRegistration> registration_;
  std::unique_ptr<OneShotRegistration> one_shot_;
  std::vector<EmbeddedPoint> targets_;
};

}  // namespace liver_sim
