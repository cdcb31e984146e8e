// Shared by the contact tests: a block on its bottom face, probes and graspers, force sums.
#pragma once

#include <string>

#include "liver_sim/simulation/liver_model.h"
#include "regions.h"

namespace liver_sim {

constexpr double kTolerance = 1e-7;  // m: ContactOptions::tolerance, the stated penetration bound

inline Scene block_scene(double E, double nu, double friction) {
  Scene s;
  s.parenchyma.young_modulus = E;
  s.parenchyma.poisson_ratio = nu;
  s.solver.tolerance = 1e-8;
  s.solver.max_iterations = 60;
  s.contact.friction = friction;
  s.contact.tolerance = kTolerance;
  s.fixed.push_back(box({-1, -1, -1}, {1, 1, 1e-9}));  // bottom face
  return s;
}

inline InstrumentOptions probe(const std::string& name, const Eigen::Vector3d& centre, double radius) {
  InstrumentOptions o;
  o.name = name;
  o.type = InstrumentOptions::Type::Probe;
  o.position = centre;
  o.radius = radius;
  return o;
}

inline InstrumentOptions grasper(double radius) {
  InstrumentOptions o;
  o.name = "grasper";
  o.type = InstrumentOptions::Type::Grasper;
  o.radius = radius;
  return o;
}

inline Eigen::Vector3d node(const LiverModel& m, int i) { return m.positions().segment<3>(3 * i); }

// Sum over nodes of a per-DOF force vector.
inline Eigen::Vector3d total(const Eigen::VectorXd& f) {
  Eigen::Vector3d s = Eigen::Vector3d::Zero();
  for (int i = 0; i < f.size(); i += 3) s += f.segment<3>(i);
  return s;
}

}  // namespace liver_sim
