// A grasper: when closed, holds the surface nodes within `radius` of its tip where they are
// (bilateral contacts); it pushes nothing.
#include <cmath>

#include "liver_sim/contact/grasper_jaws.h"
#include "liver_sim/contact/instrument_slot.h"
#include "shapes.h"

namespace liver_sim {

// A 5 mm laparoscopic grasper at a hold radius of 3 mm: jaws 18 mm long, each 1.5 mm thick,
// opened 30 degrees each way (their ends 19 mm apart); shut, centred on the tip, the hold's
// sphere lies between them.
GrasperJaws grasper_jaws(const InstrumentOptions& o) {
  const double r = o.radius;
  GrasperJaws j;
  j.hinge = 3 * r;
  j.length = 6 * r;
  j.thickness = 0.5 * r;
  j.width = 1.2 * r;
  j.opening = o.closed ? 0.0 : 30.0 * M_PI / 180.0;
  j.shaft_diameter = 1.6 * r;
  j.pin_diameter = 0.8 * r;
  return j;
}

namespace {

class Grasper final : public InstrumentShape {
 public:
  // Its jaws, as far as the hold reaches: a sphere of `radius` around the tip.
  SurfaceDistance distance(const InstrumentOptions& o, const Eigen::Isometry3d& pose,
                           const Eigen::Vector3d& x) const override {
    return probe_shape().distance(o, pose, x);
  }
  TrianglePoint deepest_point(const InstrumentOptions& o, const Eigen::Isometry3d& pose, const Eigen::Vector3d& a,
                              const Eigen::Vector3d& b, const Eigen::Vector3d& c) const override {
    return probe_shape().deepest_point(o, pose, a, b, c);
  }
  bool pushes() const override { return false; }
  double sample_spacing(const InstrumentOptions& o) const override { return 0.5 * o.radius; }
  double size(const InstrumentOptions& o) const override { return o.radius; }

  void hold(InstrumentSlot& in, double t, const Eigen::VectorXd& x, const MechanicalModel& mechanics) const override {
    const InstrumentOptions& o = in.options;
    const bool closed = o.enabled && closed_at(o, t);
    if (closed && !in.closed) {
      // The jaws close on the surface nodes within reach, where they are at this instant; on
      // the nearest surface point when they reach no node.
      const Eigen::Vector3d tip = in.pose_start.translation();
      for (int node : mechanics.boundary_nodes()) {
        if (mechanics.fixed_by_scene(node) || (x.segment<3>(3 * node) - tip).norm() > o.radius) continue;
        in.held.push_back(SurfacePoint::on_triangle(Eigen::Vector3i(node, node, node), Eigen::Vector3d(1, 0, 0)));
      }
      if (in.held.empty()) hold_nearest(in, x, mechanics);
      for (const SurfacePoint& s : in.held) in.held_local.push_back(in.pose_start.inverse() * s.at(x));
    } else if (!closed) {
      in.held.clear();
      in.held_local.clear();
    }
    in.closed = closed;
  }

  void draw(const InstrumentOptions& o, const Eigen::Isometry3d& pose, std::vector<InstrumentPart>& parts) const override {
    const GrasperJaws j = grasper_jaws(o);
    const Eigen::Isometry3d hinge = pose * Eigen::Translation3d(0, 0, j.hinge);
    for (int side : {-1, 1}) {
      // Turned about -y by side * opening, the jaw's -z runs to side * x; its inner face on the
      // axis, so that shut jaws lie side by side.
      const Eigen::Isometry3d jaw = hinge * Eigen::AngleAxisd(-side * j.opening, Eigen::Vector3d::UnitY()) *
                                    Eigen::Translation3d(side * 0.5 * j.thickness, 0, -0.5 * j.length);
      parts.push_back(part(InstrumentPart::Primitive::Box, jaw, Eigen::Vector3d(j.thickness, j.width, j.length),
                           InstrumentPart::Role::Jaw));
    }
    parts.push_back(part(InstrumentPart::Primitive::Cylinder, hinge * Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()),
                         Eigen::Vector3d(j.pin_diameter, j.pin_diameter, j.width + j.pin_diameter),
                         InstrumentPart::Role::Body));
    parts.push_back(part(InstrumentPart::Primitive::Cylinder, hinge * Eigen::Translation3d(0, 0, 0.5 * o.length),
                         Eigen::Vector3d(j.shaft_diameter, j.shaft_diameter, o.length), InstrumentPart::Role::Body));
  }

 private:
  // The nearest surface point within reach, held at least half by free nodes (as for contacts:
  // a point held at least half by the supports is theirs).
  void hold_nearest(InstrumentSlot& in, const Eigen::VectorXd& x, const MechanicalModel& mechanics) const {
    const Eigen::MatrixX3i& boundary = mechanics.boundary();
    const Eigen::Vector3d tip = in.pose_start.translation();
    double nearest = in.options.radius;
    for (int f = 0; f < boundary.rows(); ++f) {
      const Eigen::Vector3d a = x.segment<3>(3 * boundary(f, 0)), b = x.segment<3>(3 * boundary(f, 1)),
                            c = x.segment<3>(3 * boundary(f, 2));
      const TrianglePoint p = deepest_point(in.options, in.pose_start, a, b, c);
      const SurfacePoint s = SurfacePoint::on_triangle(boundary.row(f).transpose(), p.weights);
      const double distance = (s.at(x) - tip).norm();
      double supported = 0;
      for (int j = 0; j < s.count; ++j) supported += mechanics.fixed_by_scene(s.nodes[j]) ? s.weights[j] : 0.0;
      if (!(distance <= nearest) || !(supported < 0.5)) continue;
      nearest = distance;
      in.held.assign(1, s);
    }
  }
};

}  // namespace

const InstrumentShape& grasper_shape() {
  static const Grasper grasper;
  return grasper;
}

}  // namespace liver_sim
