// How each instrument shape is drawn (instrument_shape.h), against its contact geometry: the
// drawn primitives' surfaces lie on the surface the contact pushes against (surface_distance, a
// computation of its own), every part follows the instrument's pose, and the grasper's jaws open.
// Mutations killed (tried): the probe's sphere drawn with its radius for a diameter; the shaft's
// rod centred on the tip instead of half its length back; the tube's lumen drawn at the outer
// radius; the jaws not tilted when open.
#include <gtest/gtest.h>

#include <cmath>

#include "liver_sim/contact/instrument_shape.h"

namespace liver_sim {
namespace {

using Part = InstrumentPart;

InstrumentOptions shape(InstrumentOptions::Type type) {
  InstrumentOptions o;
  o.name = "tool";
  o.type = type;
  o.radius = 0.003;
  o.length = 0.04;
  o.inner_radius = 0.004;
  o.outer_radius = 0.006;
  return o;
}

// A pose away from the origin, turned about an oblique axis.
Eigen::Isometry3d pose() {
  return make_pose(Eigen::Vector3d(0.01, -0.02, 0.03),
                   Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())));
}

// Points on the side of a drawn cylinder (or the equator band of a sphere) at height z along its
// axis (m, from its centre), around its circumference.
std::vector<Eigen::Vector3d> around(const Part& p, double z) {
  std::vector<Eigen::Vector3d> points;
  for (int k = 0; k < 12; ++k) {
    const double a = 2 * M_PI * k / 12;
    points.push_back(p.pose * Eigen::Vector3d(0.5 * p.size.x() * std::cos(a), 0.5 * p.size.y() * std::sin(a), z));
  }
  return points;
}

// Points all over a drawn sphere.
std::vector<Eigen::Vector3d> over_sphere(const Part& p) {
  std::vector<Eigen::Vector3d> points;
  for (int i = 1; i < 6; ++i)
    for (int k = 0; k < 8; ++k) {
      const double polar = M_PI * i / 6, a = 2 * M_PI * k / 8;
      const Eigen::Vector3d unit(std::sin(polar) * std::cos(a), std::sin(polar) * std::sin(a), std::cos(polar));
      points.push_back(p.pose * (0.5 * p.size.x() * unit));
    }
  return points;
}

void expect_on_surface(const InstrumentOptions& o, const std::vector<Eigen::Vector3d>& points) {
  for (const Eigen::Vector3d& x : points)
    EXPECT_NEAR(surface_distance(o, pose(), x).distance, 0.0, 1e-12) << x.transpose();
}

TEST(InstrumentDrawing, AProbeIsItsContactSphere) {
  const InstrumentOptions o = shape(InstrumentOptions::Type::Probe);
  const std::vector<Part> parts = instrument_drawing(o, pose());
  ASSERT_EQ(parts.size(), 1u);
  EXPECT_EQ(parts[0].primitive, Part::Primitive::Sphere);
  EXPECT_EQ(parts[0].role, Part::Role::Body);
  expect_on_surface(o, over_sphere(parts[0]));
}

TEST(InstrumentDrawing, AShaftIsItsContactCapsule) {
  const InstrumentOptions o = shape(InstrumentOptions::Type::Shaft);
  const std::vector<Part> parts = instrument_drawing(o, pose());
  ASSERT_EQ(parts.size(), 2u);
  EXPECT_EQ(parts[0].primitive, Part::Primitive::Sphere);  // the rounded tip
  EXPECT_EQ(parts[1].primitive, Part::Primitive::Cylinder);
  // The tip's hemisphere in front of the rod, and the rod's side along its whole length.
  std::vector<Eigen::Vector3d> tip;
  for (const Eigen::Vector3d& x : over_sphere(parts[0]))
    if ((pose().inverse() * x).z() < 0) tip.push_back(x);
  expect_on_surface(o, tip);
  for (double z : {-0.45, -0.2, 0.0, 0.3, 0.45}) expect_on_surface(o, around(parts[1], z * o.length));
}

TEST(InstrumentDrawing, ATubeIsItsContactWallAroundADarkLumen) {
  const InstrumentOptions o = shape(InstrumentOptions::Type::Tube);
  const std::vector<Part> parts = instrument_drawing(o, pose());
  ASSERT_EQ(parts.size(), 2u);
  EXPECT_EQ(parts[0].role, Part::Role::Wall);
  EXPECT_EQ(parts[1].role, Part::Role::Lumen);
  // The wall's outside and the lumen's side are the wall's two faces, along the tube's length.
  for (double z : {-0.3, 0.0, 0.3}) {
    expect_on_surface(o, around(parts[0], z * o.length));
    expect_on_surface(o, around(parts[1], z * o.length));
  }
}

TEST(InstrumentDrawing, EveryPartFollowsTheInstrumentsPose) {
  for (auto type : {InstrumentOptions::Type::Probe, InstrumentOptions::Type::Shaft, InstrumentOptions::Type::Tube,
                    InstrumentOptions::Type::Grasper}) {
    const InstrumentOptions o = shape(type);
    const std::vector<Part> at_origin = instrument_drawing(o, Eigen::Isometry3d::Identity());
    const std::vector<Part> posed = instrument_drawing(o, pose());
    ASSERT_EQ(at_origin.size(), posed.size());
    ASSERT_FALSE(posed.empty());
    for (size_t i = 0; i < posed.size(); ++i) {
      EXPECT_TRUE(posed[i].pose.matrix().isApprox((pose() * at_origin[i].pose).matrix(), 1e-12)) << i;
      EXPECT_EQ(posed[i].size, at_origin[i].size);
      EXPECT_GT(posed[i].size.minCoeff(), 0.0);
    }
  }
}

TEST(InstrumentDrawing, AGraspersJawsMirrorEachOtherAndOpenApart) {
  InstrumentOptions o = shape(InstrumentOptions::Type::Grasper);
  const auto jaws = [&](bool closed) {
    o.closed = closed;
    std::vector<Part> parts = instrument_drawing(o, Eigen::Isometry3d::Identity());
    std::vector<Part> found;
    for (const Part& p : parts)
      if (p.role == Part::Role::Jaw) found.push_back(p);
    return found;
  };
  // The far end of a jaw (toward the tissue, -z) in the instrument's frame.
  const auto jaw_tip = [](const Part& p) { return Eigen::Vector3d(p.pose * Eigen::Vector3d(0, 0, -0.5 * p.size.z())); };
  for (bool closed : {true, false}) {
    const std::vector<Part> j = jaws(closed);
    ASSERT_EQ(j.size(), 2u);
    const Eigen::Vector3d a = jaw_tip(j[0]), b = jaw_tip(j[1]);
    EXPECT_NEAR(a.x(), -b.x(), 1e-15) << "mirror images across the axis";
    EXPECT_NEAR(a.z(), b.z(), 1e-15);
  }
  const double closed_gap = (jaw_tip(jaws(true)[0]) - jaw_tip(jaws(true)[1])).norm();
  const double open_gap = (jaw_tip(jaws(false)[0]) - jaw_tip(jaws(false)[1])).norm();
  EXPECT_LT(closed_gap, o.radius) << "closed, the jaws meet within the hold radius";
  EXPECT_GT(open_gap, 2 * closed_gap) << "open, their ends part";
}

}  // namespace
}  // namespace liver_sim
