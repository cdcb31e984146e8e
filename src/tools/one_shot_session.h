// One cloud registered in one shot: the one-shot registration (registration/one_shot.h) handed
// over to the tracker (SurfaceRegistration::register_one_shot, the call a tracking session makes
// for its first cloud), then the targets read from the tracked model. Shared by the register and
// register_insilico tools. The node's TrackingSession (session/tracking_session.h) makes the
// same hand-over (adopt_one_shot) with the solve on a thread of its own (one_shot_worker.h).
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <CLI/CLI.hpp>
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

// Sets the one-shot options named by `assignments` ("KEY=VALUE" each, SI units; the fields of
// OneShotOptions) and checks the result against validate()'s bounds. Throws
// std::invalid_argument for an unknown key, a value that is not a number (whole for the counts)
// or a value beyond its bound.
void set_one_shot_options(OneShotOptions& options, const std::vector<std::string>& assignments);

// The one-shot tools' --set KEY=VALUE (repeatable) into `options` (set_one_shot_options); a
// refusal is a bad command line naming it. `keys` names a few of the options for the help.
void add_one_shot_sets(CLI::App& app, OneShotOptions* options, const std::string& keys);

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
