// What an instrument of each type (InstrumentOptions::Type) is and does, ROS-free: the variation
// point of the instruments. One type per shape, each in a file of its own (probe, shaft, tube,
// grasper), with everything that differs between them: the distance to its surface and the
// deepest point of a triangle (detection), its size and how far it moves (the staging of large
// moves), what it does besides pushing (a tube's suction, a grasper's hold) and how it is drawn.
// The instruments' code (instrument_contact.h) asks shape_of(type) and names no type.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

#include "liver_sim/contact/instrument.h"
#include "liver_sim/model/mechanical_model.h"
#include "liver_sim/scene/options.h"

namespace liver_sim {

struct InstrumentSlot;

// One piece of an instrument's picture, for a viewer to turn into its own markers (the node:
// rviz markers of the same primitive, pose and size, coloured by role).
struct InstrumentPart {
  enum class Primitive {
    Sphere,    // size: the diameter along each axis
    Cylinder,  // along its local z; size: diameter, diameter, length
    Box        // size: its edges along its local x, y, z
  };
  enum class Role {
    Body,   // the instrument's solid body
    Wall,   // a tube's wall, seen through (the tissue it sucks stays visible)
    Lumen,  // the hollow inside a wall, dark
    Jaw     // a grasper's jaw
  };
  Primitive primitive = Primitive::Sphere;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // its centre and axes, in the instruments' frame
  Eigen::Vector3d size = Eigen::Vector3d::Zero();           // m, full extents (see Primitive)
  Role role = Role::Body;
};

class InstrumentShape {
 public:
  virtual ~InstrumentShape() = default;

  // Distance from x to the instrument's surface (m, < 0 inside) and the outward normal there.
  virtual SurfaceDistance distance(const InstrumentOptions& o, const Eigen::Isometry3d& pose,
                                   const Eigen::Vector3d& x) const = 0;
  // The point of triangle (a, b, c) deepest inside the instrument, or nearest to it (instrument.h).
  virtual TrianglePoint deepest_point(const InstrumentOptions& o, const Eigen::Isometry3d& pose,
                                      const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                      const Eigen::Vector3d& c) const = 0;

  // Contact: whether it pushes the surface (unilateral contacts at surface samples at most
  // sample_spacing apart, its large moves staged), or only holds what it holds (hold()).
  virtual bool pushes() const { return true; }
  virtual double sample_spacing(const InstrumentOptions& o) const = 0;
  // Staging: its size (m; a stage travels at most a quarter of it, and a contact point deeper
  // than a quarter of it is deep), and how far its farthest point moves between two poses.
  virtual double size(const InstrumentOptions& o) const = 0;
  virtual double travel(const InstrumentOptions& o, const Eigen::Isometry3d& from, const Eigen::Isometry3d& to) const;

  // Suction: whether it has a pressure load in the mechanical model, and that load at x (the
  // pressure below ambient on the boundary triangles in its lumen; none when it has none).
  virtual bool sucks() const { return false; }
  virtual void suction(const InstrumentOptions& o, const Eigen::Isometry3d& pose, const Eigen::MatrixX3i& boundary,
                       const Eigen::VectorXd& x, PressureLoad& load) const;
  // Holding: at the start of a step at time t, the surface points the instrument holds from now
  // on (instrument_slot.h: held, held_local, closed), taken from x. Nothing for most shapes.
  virtual void hold(InstrumentSlot&, double /*t*/, const Eigen::VectorXd& /*x*/, const MechanicalModel&) const {}

  // Its picture at pose: parts appended to `parts`.
  virtual void draw(const InstrumentOptions& o, const Eigen::Isometry3d& pose, std::vector<InstrumentPart>& parts) const = 0;
};

const InstrumentShape& shape_of(InstrumentOptions::Type type);

// The instrument's picture at its pose (a viewer draws the instruments in the scene).
std::vector<InstrumentPart> instrument_drawing(const InstrumentOptions& o, const Eigen::Isometry3d& pose);

}  // namespace liver_sim
