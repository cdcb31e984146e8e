// The instrument shapes (instrument_shape.h), each defined in its own file, and what they share.
#pragma once

#include "liver_sim/contact/instrument_shape.h"

namespace liver_sim {

const InstrumentShape& probe_shape();
const InstrumentShape& shaft_shape();
const InstrumentShape& tube_shape();
const InstrumentShape& grasper_shape();

// Nearest point of a sphere of radius r around c: along the radius, or along `fallback` at c.
SurfaceDistance around_point(const Eigen::Vector3d& x, const Eigen::Vector3d& c, double r,
                             const Eigen::Vector3d& fallback);

// How far the farther of a rod's ends (its tip and the point `length` back along +z) moves.
double rod_travel(double length, const Eigen::Isometry3d& from, const Eigen::Isometry3d& to);

// The point of triangle (a, b, c) with barycentric weights w, and the shape's distance there.
TrianglePoint triangle_point(const InstrumentShape& shape, const InstrumentOptions& o, const Eigen::Isometry3d& pose,
                             const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                             const Eigen::Vector3d& w);

// A part of a picture (instrument_shape.h).
InstrumentPart part(InstrumentPart::Primitive primitive, const Eigen::Isometry3d& pose, const Eigen::Vector3d& size,
                    InstrumentPart::Role role);

}  // namespace liver_sim
