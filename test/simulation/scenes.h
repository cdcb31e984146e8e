// Shared by the simulation tests: scenes from config/scenes, instruments pressing into a cube.
#pragma once

#include <string>

#include "liver_sim/simulation/liver_model.h"
#include "source_files.h"

namespace liver_sim {

using Fault = NewtonStepper::InjectedFault;
using Type = InstrumentOptions::Type;

// An instrument of `type` pressing further into the top face of a 15 mm cube at every step of
// the scene's pseudo-time, so that each step has work to do (tip positions in mm).
inline InstrumentOptions pressing(Type type, const Eigen::Vector3d& from_mm, const Eigen::Vector3d& to_mm, double until) {
  InstrumentOptions o;
  o.name = "instrument";
  o.type = type;
  o.radius = 0.002;
  o.length = 0.01;
  o.trajectory.resize(2);
  o.trajectory[0].position = 1e-3 * from_mm;
  o.trajectory[1].t = until;
  o.trajectory[1].position = 1e-3 * to_mm;
  o.position = o.trajectory[0].position;
  return o;
}

// The probe cube (6 x 6 x 6 hexahedra, friction 0.3) with one instrument of the type, or the
// aspiration tube's scene (a tube with 3 kPa of suction, as the issue measured it) pressed down.
inline Scene scene_with(Type type) {
  if (type == Type::Tube) {
    Scene s = load_scene(source("config/scenes/aspiration_tube.yaml"));
    s.mesh.box_divisions = Eigen::Vector3i(6, 6, 6);
    InstrumentOptions& tube = s.instruments[0];
    tube.trajectory.resize(2);
    tube.trajectory[0].position = tube.position;
    tube.trajectory[1].t = 0.05;
    tube.trajectory[1].position = tube.position - Eigen::Vector3d(0, 0, 0.5e-3);
    return s;
  }
  Scene s = load_scene(source("config/scenes/probe_cube.yaml"));
  s.mesh.box_divisions = Eigen::Vector3i(6, 6, 6);
  switch (type) {
    case Type::Probe:  // a 2 mm sphere, 0.3 mm further per step
      s.instruments.push_back(pressing(type, {7.5, 7.5, 17}, {7.5, 7.5, 14}, 0.01));
      break;
    case Type::Shaft:  // a 2 mm rod lying across the top face, turned onto x, pressed down
      s.instruments.push_back(pressing(type, {2.5, 7.5, 17}, {2.5, 7.5, 14}, 0.01));
      s.instruments.back().orientation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));
      for (auto& k : s.instruments.back().trajectory) k.orientation = s.instruments.back().orientation;
      break;
    case Type::Grasper:  // closes on the top face's centre and lifts it 0.2 mm per step
      s.instruments.push_back(pressing(type, {7.5, 7.5, 15}, {7.5, 7.5, 17}, 0.01));
      s.instruments.back().trajectory[0].closed = true;
      break;
    case Type::Tube:
      break;
  }
  return s;
}

// The aspiration cube (4 x 4 x 4 hexahedra, capsule, 3 kPa of suction) in static mode.
inline Scene aspiration_cube() {
  Scene s = load_scene(source("config/scenes/aspiration_cube.yaml"));
  s.mesh.box_divisions = Eigen::Vector3i(4, 4, 4);
  return s;
}

}  // namespace liver_sim
