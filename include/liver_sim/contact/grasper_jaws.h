// A grasper's picture (grasper.cpp draws it; a viewer's test checks the drawing against it): a
// laparoscopic grasper as a surgeon sees one, its sizes in hold radii. The jaws hinge on the
// axis at the shaft's end and reach past the tip (the hold point between them); shut when the
// grasper is closed, each turned `opening` off the axis when it is open.
#pragma once

#include "liver_sim/scene/options.h"

namespace liver_sim {

struct GrasperJaws {
  double hinge;           // m, from the tip back along +z: the shaft's end, the jaws' pivot
  double length;          // m, of each jaw from the hinge
  double thickness;       // m, of each jaw across the opening plane (the local x-z plane)
  double width;           // m, of each jaw along the hinge (local y)
  double opening;         // rad, each jaw off the axis, one to +x, one to -x; 0 when closed
  double shaft_diameter;  // m
  double pin_diameter;    // m, the hinge pin across the jaws, along y, wider than them
};

GrasperJaws grasper_jaws(const InstrumentOptions& o);

}  // namespace liver_sim
