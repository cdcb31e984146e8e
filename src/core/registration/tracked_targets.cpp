#include "liver_sim/registration/tracked_targets.h"

namespace liver_sim {

std::vector<TrackedTarget> tracked_targets(const LiverModel& model) {
  std::vector<TrackedTarget> targets;
  for (int i = 0; i < model.num_probes(); ++i)
    targets.push_back({model.probe_name(i), TrackedTarget::Kind::Probe, model.probe_position(i)});
  if (model.num_beams() == 0) return targets;
  std::vector<int> degree(model.num_vessel_nodes(), 0), vessel(model.num_vessel_nodes(), 0);
  const Eigen::MatrixX2i& segments = model.beam_segments();
  for (int e = 0; e < segments.rows(); ++e)
    for (int end = 0; end < 2; ++end) {
      ++degree[segments(e, end)];
      vessel[segments(e, end)] = model.beam_vessel(e);
    }
  for (int k = 0; k < model.num_vessel_nodes(); ++k)
    if (degree[k] >= 3)
      targets.push_back({model.vessel_name(vessel[k]) + " bifurcation " + std::to_string(k),
                         TrackedTarget::Kind::Bifurcation, model.vessel_node_position(k)});
  return targets;
}

}  // namespace liver_sim
