// Model and solver options, SI units throughout, and their validation. Plain data: filled from
// a scene file, from ROS parameters or by code.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/region.h"

namespace liver_sim {

enum class RotationMethod {
  Geometric,  // edge frame of the element (Nesme, Payan, Faure 2005); depends on vertex order
  Polar       // polar decomposition of F by SVD, inversion-safe (Irving, Teran, Fedkiw 2004)
};

struct ParenchymaOptions {
  double young_modulus = 3500.0;  // Pa
  double poisson_ratio = 0.45;    // -, in (-1, 0.5)
  double density = 1060.0;        // kg/m^3
  RotationMethod rotation = RotationMethod::Polar;
};

struct CapsuleOptions {
  bool enabled = false;
  double young_modulus = 8.22e6;  // Pa
  double thickness = 20e-6;       // m
  double poisson_ratio = 0.45;    // -, in (-1, 0.5)
  std::optional<Region> region;   // boundary triangles whose centroid lies inside; all if unset
};

// One vascular tree embedded in the parenchyma (beam elements; see corotational_beam.h).
struct VesselOptions {
  std::string name;                // for messages and output
  std::string file;                // .vtk or .yaml centre-line graph (vessel_tree.h)
  double scale = 1.0;              // file units -> m
  bool enabled = true;
  double young_modulus = 0.62e6;   // Pa, vessel wall (porcine hepatic vein at small strain)
  double poisson_ratio = 0.45;     // -, in (-1, 0.5)
  double snap_tolerance = 1e-3;    // m: nodes at most this far outside the mesh are moved onto it
};

struct LoadOptions {
  enum class Kind {
    Pressure,  // follower pressure on boundary triangles of `region` (Pa, >0 pushes inward)
    Gravity,   // body force: acceleration (m/s^2) times lumped mass
    Force      // total force (N) spread equally over the nodes of `region`
  };
  Kind kind = Kind::Pressure;
  double pressure = 0.0;                          // Pa
  Eigen::Vector3d vector = Eigen::Vector3d::Zero();  // m/s^2 (gravity) or N (force)
  std::optional<Region> region;                   // all boundary triangles if unset (pressure)
};

struct SolverOptions {
  enum class Mode { Static, Dynamic };
  Mode mode = Mode::Static;
  double dt = 0.01;               // s, time step of the dynamic mode
  int steps = 1;                  // static: load increments; dynamic: time steps
  int max_iterations = 30;        // Newton iterations per step (cap)
  double tolerance = 1e-6;        // force residual, relative to the external load norm
  bool line_search = true;        // backtracking on the residual norm
  double rayleigh_mass = 0.0;     // 1/s, damping D = a M + b K
  double rayleigh_stiffness = 0.0;  // s
};

struct ProbeOptions {
  std::string name;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();  // rest position (m)
};

// Empty string when valid, else a message naming the field at fault.
std::string validate(const ParenchymaOptions& o);
std::string validate(const CapsuleOptions& o);
std::string validate(const SolverOptions& o);
std::string validate(const Region& r);
std::string validate(const VesselOptions& o);  // field names prefixed with "vessels.<name>."

}  // namespace liver_sim
