// A shaft: a capsule, a cylinder of `radius` from the tip to `length` back along +z with
// rounded ends.
#include <algorithm>

#include "liver_sim/geometry/closest_points.h"
#include "shapes.h"

namespace liver_sim {
namespace {

class Shaft final : public InstrumentShape {
 public:
  SurfaceDistance distance(const InstrumentOptions& o, const Eigen::Isometry3d& pose,
                           const Eigen::Vector3d& x) const override {
    // From the nearest point of the axis segment; a point on the axis is pushed out of the tip (-z).
    const Eigen::Vector3d axis = pose.linear().col(2);
    const Eigen::Vector3d tip = pose.translation();
    const double s = std::clamp((x - tip).dot(axis), 0.0, o.length);
    return around_point(x, tip + s * axis, o.radius, -axis);
  }
  TrianglePoint deepest_point(const InstrumentOptions& o, const Eigen::Isometry3d& pose, const Eigen::Vector3d& a,
                              const Eigen::Vector3d& b, const Eigen::Vector3d& c) const override {
    const Eigen::Vector3d tip = pose.translation();
    return triangle_point(*this, o, pose, a, b, c,
                          closest_segment_triangle(tip, tip + o.length * pose.linear().col(2), a, b, c).weights);
  }
  double sample_spacing(const InstrumentOptions& o) const override { return 0.5 * o.radius; }
  double size(const InstrumentOptions& o) const override { return o.radius; }
  // Turned, it travels farthest at one of its ends.
  double travel(const InstrumentOptions& o, const Eigen::Isometry3d& from, const Eigen::Isometry3d& to) const override {
    return rod_travel(o.length, from, to);
  }
  void draw(const InstrumentOptions& o, const Eigen::Isometry3d& pose, std::vector<InstrumentPart>& parts) const override {
    using P = InstrumentPart::Primitive;
    parts.push_back(part(P::Sphere, pose, Eigen::Vector3d::Constant(2 * o.radius), InstrumentPart::Role::Body));
    parts.push_back(part(P::Cylinder, pose * Eigen::Translation3d(0, 0, 0.5 * o.length),
                         Eigen::Vector3d(2 * o.radius, 2 * o.radius, o.length), InstrumentPart::Role::Body));
  }
};

}  // namespace

const InstrumentShape& shaft_shape() {
  static const Shaft shaft;
  return shaft;
}

}  // namespace liver_sim
