#include "liver_sim/contact/instrument_shape.h"

#include <algorithm>

#include "shapes.h"

namespace liver_sim {

const InstrumentShape& shape_of(InstrumentOptions::Type type) {
  switch (type) {
    case InstrumentOptions::Type::Probe: return probe_shape();
    case InstrumentOptions::Type::Shaft: return shaft_shape();
    case InstrumentOptions::Type::Tube: return tube_shape();
    case InstrumentOptions::Type::Grasper: return grasper_shape();
  }
  return probe_shape();
}

std::vector<InstrumentPart> instrument_drawing(const InstrumentOptions& o, const Eigen::Isometry3d& pose) {
  std::vector<InstrumentPart> parts;
  shape_of(o.type).draw(o, pose, parts);
  return parts;
}

double InstrumentShape::travel(const InstrumentOptions&, const Eigen::Isometry3d& from, const Eigen::Isometry3d& to) const {
  return (to.translation() - from.translation()).norm();
}

void InstrumentShape::suction(const InstrumentOptions&, const Eigen::Isometry3d&, const Eigen::MatrixX3i&,
                              const Eigen::VectorXd&, PressureLoad& load) const {
  load.pressure = 0.0;
  load.triangles.clear();
}

double rod_travel(double length, const Eigen::Isometry3d& from, const Eigen::Isometry3d& to) {
  const Eigen::Vector3d far_end(0, 0, length);
  return std::max((to.translation() - from.translation()).norm(), (to * far_end - from * far_end).norm());
}

SurfaceDistance around_point(const Eigen::Vector3d& x, const Eigen::Vector3d& c, double r,
                             const Eigen::Vector3d& fallback) {
  const Eigen::Vector3d d = x - c;
  const double n = d.norm();
  SurfaceDistance s;
  s.distance = n - r;
  s.normal = n > 1e-12 * r ? Eigen::Vector3d(d / n) : fallback;
  return s;
}

TrianglePoint triangle_point(const InstrumentShape& shape, const InstrumentOptions& o, const Eigen::Isometry3d& pose,
                             const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                             const Eigen::Vector3d& w) {
  TrianglePoint p;
  p.weights = w;
  p.distance = shape.distance(o, pose, Eigen::Vector3d(w[0] * a + w[1] * b + w[2] * c));
  return p;
}

InstrumentPart part(InstrumentPart::Primitive primitive, const Eigen::Isometry3d& pose, const Eigen::Vector3d& size,
                    InstrumentPart::Role role) {
  InstrumentPart p;
  p.primitive = primitive;
  p.pose = pose;
  p.size = size;
  p.role = role;
  return p;
}

}  // namespace liver_sim
