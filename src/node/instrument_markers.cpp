#include "instrument_markers.h"

#include <cmath>

#include "msg_conversion.h"

namespace liver_sim {

visualization_msgs::MarkerArray instrument_markers(const LiverModel& model, const std::vector<InstrumentSlots::Slot>& slots,
                                                   const std_msgs::Header& header) {
  using visualization_msgs::Marker;
  visualization_msgs::MarkerArray a;
  Marker clear;
  clear.header = header;
  clear.ns = "instruments";
  clear.action = Marker::DELETEALL;
  a.markers.push_back(clear);
  int id = 0;
  auto part = [&](int type, const Eigen::Isometry3d& pose, const Eigen::Vector3d& scale, float grey, float alpha) {
    Marker m;
    m.header = header;
    m.ns = "instruments";
    m.id = id++;
    m.type = type;
    m.action = Marker::ADD;
    m.pose = to_pose(pose);
    m.scale = to_vector(scale);
    m.color.r = m.color.g = grey;
    m.color.b = grey + 0.05f;
    m.color.a = alpha;
    a.markers.push_back(m);
  };
  using Type = InstrumentOptions::Type;
  for (const InstrumentSlots::Slot& s : slots) {
    if (s.index < 0 || !model.instrument(s.index).enabled) continue;
    const InstrumentOptions& o = model.instrument(s.index);
    const Eigen::Isometry3d& P = model.instrument_pose(s.index);
    const auto along = [&](double z) { return P * Eigen::Translation3d(0, 0, z); };
    switch (o.type) {
      case Type::Probe:
        part(Marker::SPHERE, P, Eigen::Vector3d::Constant(2 * o.radius), 0.75f, 1.0f);
        break;
      case Type::Shaft:
        part(Marker::SPHERE, P, Eigen::Vector3d::Constant(2 * o.radius), 0.75f, 1.0f);
        part(Marker::CYLINDER, along(0.5 * o.length), Eigen::Vector3d(2 * o.radius, 2 * o.radius, o.length), 0.75f, 1.0f);
        break;
      case Type::Tube:
        part(Marker::CYLINDER, along(0.5 * o.length), Eigen::Vector3d(2 * o.outer_radius, 2 * o.outer_radius, o.length),
             0.8f, 0.5f);
        part(Marker::CYLINDER, along(0.5 * o.length + 1e-4),
             Eigen::Vector3d(2 * o.inner_radius, 2 * o.inner_radius, o.length), 0.2f, 1.0f);
        break;
      case Type::Grasper: {
        // Jaws of twice the hold radius, tilted apart by 25 degrees when open.
        const double r = o.radius, tilt = o.closed ? 0.0 : 25.0 * M_PI / 180.0;
        for (int side : {-1, 1}) {
          const Eigen::Isometry3d jaw = P * Eigen::Translation3d(0, 0, r) * Eigen::AngleAxisd(side * tilt, Eigen::Vector3d::UnitY()) *
                                        Eigen::Translation3d(side * 0.25 * r, 0, -r);
          part(Marker::CUBE, jaw, Eigen::Vector3d(0.3 * r, 0.8 * r, 2 * r), 0.55f, 1.0f);
        }
        part(Marker::CYLINDER, along(r + 0.5 * o.length), Eigen::Vector3d(0.8 * r, 0.8 * r, o.length), 0.75f, 1.0f);
        break;
      }
    }
  }
  return a;
}

}  // namespace liver_sim
