#include "instrument_markers.h"

#include "liver_sim/contact/instrument_shape.h"
#include "msg_conversion.h"

namespace liver_sim {
namespace {

using visualization_msgs::Marker;

int marker_type(InstrumentPart::Primitive p) {
  switch (p) {
    case InstrumentPart::Primitive::Sphere: return Marker::SPHERE;
    case InstrumentPart::Primitive::Cylinder: return Marker::CYLINDER;
    case InstrumentPart::Primitive::Box: return Marker::CUBE;
  }
  return Marker::SPHERE;
}

// Steel grey; a tube's wall seen through, its lumen dark, a grasper's jaws darker than its shaft.
void paint(InstrumentPart::Role role, std_msgs::ColorRGBA& c) {
  float grey = 0.75f;
  c.a = 1.0f;
  switch (role) {
    case InstrumentPart::Role::Body: break;
    case InstrumentPart::Role::Wall: grey = 0.8f, c.a = 0.5f; break;
    case InstrumentPart::Role::Lumen: grey = 0.2f; break;
    case InstrumentPart::Role::Jaw: grey = 0.6f; break;
  }
  c.r = c.g = grey;
  c.b = grey + 0.05f;
}

}  // namespace

visualization_msgs::MarkerArray instrument_markers(const LiverModel& model, const std::vector<InstrumentSlots::Slot>& slots,
                                                   const std_msgs::Header& header) {
  visualization_msgs::MarkerArray a;
  Marker clear;
  clear.header = header;
  clear.ns = "instruments";
  clear.action = Marker::DELETEALL;
  a.markers.push_back(clear);
  int id = 0;
  for (const InstrumentSlots::Slot& s : slots) {
    if (s.index < 0 || !model.instrument(s.index).enabled) continue;
    for (const InstrumentPart& p : instrument_drawing(model.instrument(s.index), model.instrument_pose(s.index))) {
      Marker m;
      m.header = header;
      m.ns = "instruments";
      m.id = id++;
      m.type = marker_type(p.primitive);
      m.action = Marker::ADD;
      m.pose = to_pose(p.pose);
      m.scale = to_vector(p.size);
      paint(p.role, m.color);
      a.markers.push_back(m);
    }
  }
  return a;
}

}  // namespace liver_sim
