#include "liver_sim/contact/instrument.h"

#include <algorithm>

#include "liver_sim/contact/instrument_shape.h"

namespace liver_sim {

Eigen::Isometry3d make_pose(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  // Scaled without squaring: a quaternion of 1e200 is a rotation too (its norm() overflows).
  T.linear() = Eigen::Quaterniond(orientation.coeffs() / orientation.coeffs().stableNorm()).toRotationMatrix();
  T.translation() = position;
  return T;
}

SurfaceDistance surface_distance(const InstrumentOptions& shape, const Eigen::Isometry3d& pose,
                                 const Eigen::Vector3d& x) {
  return shape_of(shape.type).distance(shape, pose, x);
}

TrianglePoint deepest_point(const InstrumentOptions& shape, const Eigen::Isometry3d& pose, const Eigen::Vector3d& a,
                            const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  return shape_of(shape.type).deepest_point(shape, pose, a, b, c);
}

Eigen::Isometry3d pose_at(const InstrumentOptions& o, double t) {
  const auto& path = o.trajectory;
  if (path.empty()) return make_pose(o.position, o.orientation);
  if (t <= path.front().t) return make_pose(path.front().position, path.front().orientation);
  if (t >= path.back().t) return make_pose(path.back().position, path.back().orientation);
  const auto next = std::upper_bound(path.begin(), path.end(), t,
                                     [](double v, const InstrumentOptions::Keyframe& k) { return v < k.t; });
  const auto& b = *next;
  const auto& a = *(next - 1);
  const double s = (t - a.t) / (b.t - a.t);
  return make_pose((1 - s) * a.position + s * b.position,
                   a.orientation.normalized().slerp(s, b.orientation.normalized()));
}

bool closed_at(const InstrumentOptions& o, double t) {
  bool closed = o.closed;
  for (const InstrumentOptions::Keyframe& k : o.trajectory)
    if (k.t <= t && k.closed) closed = *k.closed;
  return closed;
}

}  // namespace liver_sim
