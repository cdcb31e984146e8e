// The node's instrument markers (src/node/instrument_markers.h) of a grasper, against the jaws'
// geometry computed here from their sizes (grasper_jaws.h) by trigonometry in the instrument's
// frame: the jaws hinge at the shaft's end, one on each side of its axis, their far ends
// 2 (length sin(opening) + thickness/2 cos(opening)) apart (open: the ends part; closed: the
// jaws side by side, one thickness across), everything where the instrument's pose puts it.
// Mutations killed (tried): both jaws turned the same way (+opening for both sides).
#include <gtest/gtest.h>

#include <cmath>

#include "instrument_markers.h"
#include "liver_sim/contact/grasper_jaws.h"
#include "liver_sim/geometry/mesh.h"
#include "liver_sim/scene/scene.h"
#include "node/markers.h"
#include "regions.h"

namespace liver_sim {
namespace {

using visualization_msgs::Marker;

// A pose away from the origin, turned about an oblique axis.
const Eigen::Vector3d kTip(0.01, -0.02, 0.03);
const Eigen::Quaterniond kTurn(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()));

Eigen::Quaterniond orientation(const Marker& m) {
  return {m.pose.orientation.w, m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z};
}
// The centre of the marker's end face toward its local -z (or +z).
Eigen::Vector3d end(const Marker& m, double sign) {
  return position(m) + orientation(m) * Eigen::Vector3d(0, 0, sign * 0.5 * m.scale.z);
}

struct Drawn {
  std::vector<Marker> jaws, cylinders;
};

// The markers of a grasper posed at kTip, kTurn, closed or open, on a 2 cm box.
Drawn draw_grasper(bool closed, InstrumentOptions& o) {
  Scene s;
  s.fixed.push_back(box({-1, -1, -1}, {1, 1, 0}));
  LiverModel model(make_box_mesh({0.02, 0.02, 0.02}, {2, 2, 2}), s);
  o.name = "jaws";
  o.type = InstrumentOptions::Type::Grasper;
  o.radius = 0.003;
  o.length = 0.1;
  o.closed = closed;
  o.position = kTip;
  o.orientation = kTurn;
  InstrumentSlots::Slot slot;
  slot.name = o.name;
  slot.index = model.add_instrument(o);
  std_msgs::Header header;
  header.frame_id = "liver";
  const visualization_msgs::MarkerArray a = instrument_markers(model, {slot}, header);
  Drawn d;
  EXPECT_EQ(a.markers.front().action, Marker::DELETEALL);
  for (const Marker& m : a.markers) {
    if (m.action != Marker::ADD) continue;
    EXPECT_EQ(m.header.frame_id, "liver");
    if (m.type == Marker::CUBE) d.jaws.push_back(m);
    if (m.type == Marker::CYLINDER) d.cylinders.push_back(m);
  }
  return d;
}

TEST(InstrumentMarkers, AGraspersJawsHingeAtItsShaftsEndAndOpenBySide) {
  for (bool closed : {true, false}) {
    SCOPED_TRACE(closed ? "closed" : "open");
    InstrumentOptions o;
    const Drawn d = draw_grasper(closed, o);
    const GrasperJaws j = grasper_jaws(o);
    EXPECT_EQ(j.opening == 0.0, closed);
    ASSERT_EQ(d.jaws.size(), 2u);
    ASSERT_EQ(d.cylinders.size(), 2u);  // the hinge pin and the shaft
    const Marker& shaft = d.cylinders[0].scale.z > d.cylinders[1].scale.z ? d.cylinders[0] : d.cylinders[1];
    const Marker& pin = &shaft == &d.cylinders[0] ? d.cylinders[1] : d.cylinders[0];

    // In the instrument's frame (tip at the origin, +z back along the shaft), by trigonometry.
    const Eigen::Vector3d hinge(0, 0, j.hinge);
    const double c = std::cos(j.opening), s = std::sin(j.opening);
    const auto world = [&](const Eigen::Vector3d& local) { return Eigen::Vector3d(kTip + kTurn * local); };
    EXPECT_TRUE(end(shaft, -1).isApprox(world(hinge), 1e-12)) << "the shaft ends at the hinge";
    EXPECT_TRUE(end(shaft, +1).isApprox(world(hinge + Eigen::Vector3d(0, 0, o.length)), 1e-12));
    EXPECT_NEAR(shaft.scale.x, j.shaft_diameter, 1e-15);
    EXPECT_TRUE(position(pin).isApprox(world(hinge), 1e-12)) << "the pin on the hinge";
    EXPECT_NEAR(std::abs((orientation(pin) * Eigen::Vector3d::UnitZ()).dot(kTurn * Eigen::Vector3d::UnitY())), 1.0, 1e-12)
        << "the pin across the opening plane";

    const Eigen::Vector3d axis = kTurn * Eigen::Vector3d::UnitX();  // across the shaft, in the opening plane
    std::vector<double> sides;
    for (const Marker& jaw : d.jaws) {
      EXPECT_NEAR(jaw.scale.x, j.thickness, 1e-15);
      EXPECT_NEAR(jaw.scale.y, j.width, 1e-15);
      EXPECT_NEAR(jaw.scale.z, j.length, 1e-15);
      const double side = (position(jaw) - kTip).dot(axis) > 0 ? 1.0 : -1.0;
      sides.push_back(side);
      // The jaw's axis runs from the hinge along (side sin, 0, -cos), its centre line half a
      // thickness outward of it: near end at the hinge, far end a jaw's length along.
      const Eigen::Vector3d outward = 0.5 * j.thickness * Eigen::Vector3d(side * c, 0, s);
      EXPECT_TRUE(end(jaw, +1).isApprox(world(hinge + outward), 1e-12)) << "side " << side;
      EXPECT_TRUE(end(jaw, -1).isApprox(world(hinge + j.length * Eigen::Vector3d(side * s, 0, -c) + outward), 1e-12))
          << "side " << side;
    }
    EXPECT_EQ(sides[0] + sides[1], 0.0) << "one jaw on each side of the shaft's axis";
    const double gap = (end(d.jaws[0], -1) - end(d.jaws[1], -1)).norm();
    EXPECT_NEAR(gap, 2 * (j.length * s + 0.5 * j.thickness * c), 1e-12);
    if (closed) {
      EXPECT_NEAR(gap, j.thickness, 1e-12) << "shut: side by side";
    } else {
      EXPECT_GT(gap, 2 * o.radius) << "open: the hold's sphere fits between the ends";
    }
  }
}

}  // namespace
}  // namespace liver_sim
