// A probe: a sphere of `radius` around its tip.
#include "liver_sim/geometry/closest_points.h"
#include "shapes.h"

namespace liver_sim {
namespace {

class Probe final : public InstrumentShape {
 public:
  SurfaceDistance distance(const InstrumentOptions& o, const Eigen::Isometry3d& pose,
                           const Eigen::Vector3d& x) const override {
    // A point at the centre is pushed out of the tip (-z).
    return around_point(x, pose.translation(), o.radius, -pose.linear().col(2));
  }
  TrianglePoint deepest_point(const InstrumentOptions& o, const Eigen::Isometry3d& pose, const Eigen::Vector3d& a,
                              const Eigen::Vector3d& b, const Eigen::Vector3d& c) const override {
    return triangle_point(*this, o, pose, a, b, c, closest_on_triangle(pose.translation(), a, b, c));
  }
  // A curved tip sinks between samples half its radius apart by at most 1/32 of the radius.
  double sample_spacing(const InstrumentOptions& o) const override { return 0.5 * o.radius; }
  double size(const InstrumentOptions& o) const override { return o.radius; }
  void draw(const InstrumentOptions& o, const Eigen::Isometry3d& pose, std::vector<InstrumentPart>& parts) const override {
    parts.push_back(part(InstrumentPart::Primitive::Sphere, pose, Eigen::Vector3d::Constant(2 * o.radius),
                         InstrumentPart::Role::Body));
  }
};

}  // namespace

const InstrumentShape& probe_shape() {
  static const Probe probe;
  return probe;
}

}  // namespace liver_sim
