// Model and solver options, SI units throughout, and their validation. Plain data: filled from
// a scene file, from ROS parameters or by code.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/geometry/region.h"

namespace liver_sim {

enum class RotationMethod {
  Geometric,  // edge frame of the element (Nesme, Payan, Faure 2005); depends on vertex order
  Polar       // polar decomposition of F by SVD, inversion-safe (Irving, Teran, Fedkiw 2004)
};

// Limits: validate() refuses a value beyond its field's bounds (given beside each field, SI units)
// with a message naming the field and the bound. The upper bounds keep the work and memory of a
// step bounded (instrument sizes set the contact sampling, travel the stages, counts the loops)
// or lie far beyond any tissue (moduli, thicknesses), where a value is a unit error.

struct ParenchymaOptions {
  double young_modulus = 3500.0;  // Pa, in (0, 1e9]
  double poisson_ratio = 0.45;    // -, in (-1, 0.5)
  double density = 1060.0;        // kg/m^3, in (0, 1e5]
  RotationMethod rotation = RotationMethod::Polar;
};

struct CapsuleOptions {
  bool enabled = false;
  double young_modulus = 8.22e6;  // Pa, in (0, 1e10]: Glisson's capsule is ~10 MPa, steel 2e11
  double thickness = 20e-6;       // m, in (0, 1e-3]: Glisson's capsule is 20-100 um
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

  static LoadOptions gravity(const Eigen::Vector3d& acceleration) {  // m/s^2
    LoadOptions g;
    g.kind = Kind::Gravity;
    g.vector = acceleration;
    return g;
  }
};

struct SolverOptions {
  enum class Mode { Static, Dynamic };
  // How each Newton iteration solves for its update (doc/performance.md). With instrument
  // contacts, ModifiedNewton and FullNewton carry the contact forces in their direct solve; the
  // others use NewtonKrylov with the contact rows.
  enum class Strategy {
    NewtonKrylov,     // GMRES on the true Jacobian, an earlier CHOLMOD factor as preconditioner
    FullNewton,       // the tangent refactorised (CHOLMOD) and solved directly every iteration
    FullNewtonEigen,  // the same with Eigen's SimplicialLDLT
    ReusedFactorCG,   // conjugate gradients on the current tangent, an earlier factor as preconditioner
    CG,               // conjugate gradients on the current tangent, Jacobi preconditioner
    ModifiedNewton    // an earlier factor solved directly; refreshed when the residual falls slowly
  };
  // Where a dynamic step's Newton iteration starts (doc/performance.md); the converged
  // step does not depend on it, a capped real-time frame does.
  enum class Predictor {
    None,                 // x_n: Newton starts at the last state
    ConstantVelocity,     // x_n + dt v_n
    ConstantAcceleration  // x_n + dt v_n + dt^2 a_n, a_n = (v_n - v_n-1) / dt
  };
  Mode mode = Mode::Static;
  Strategy strategy = Strategy::NewtonKrylov;
  Predictor predictor = Predictor::ConstantVelocity;
  double dt = 0.01;               // s, time step of the dynamic mode, in (0, 10]
  int steps = 1;                  // static: load increments; dynamic: time steps; in [1, 1e6]
  int max_iterations = 30;        // Newton iterations per step (cap), in [1, 10000]
  double tolerance = 1e-6;        // force residual, relative to the external load norm
  bool line_search = true;        // backtracking on the residual norm
  double rayleigh_mass = 0.0;     // 1/s, damping D = a M + b K
  double rayleigh_stiffness = 0.0;  // s
  // Threads of the element loops, in [1, 64] (worker_pool.h). One suits a computer that other
  // programs share; more gain only on idle, independent cores (doc/performance.md). Results do
  // not depend on it, to the last bit.
  int threads = 1;
  // Wall time a step may take (s), in (0, inf]. Past it the step ends after the Newton iteration
  // or instrument stage in progress, NotConverged, and the next step continues from its iterate
  // (newton_stepper.h). The first iteration of a step always runs, so that frames progress.
  double time_budget = std::numeric_limits<double>::infinity();
  // With a time budget: a step that reaches max_iterations with its residual (relative, as
  // tolerance) above this iterates on, within half the budget, to 50 iterations; in (0, inf].
  // Infinity turns it off; in a scene, whose YAML cannot give inf, 1e6 does (newton_stepper.h,
  // doc/robustness.md#frames-far-from-equilibrium).
  double capped_residual = 3e-3;
  // The strategies that keep a factor (modified Newton, Newton-Krylov, reused-factor CG): a
  // refresh their judgement of the factor asks for is factorised on a thread of its own at a
  // lower priority while the iterations go on with the old factor, and replaces it when done
  // (background_factorization.h); the other refreshes (the first factor, a changed model, an
  // iteration without descent) stay in the step. Results then depend on timing. The other
  // strategies ignore it.
  bool background_refresh = false;
};

struct ProbeOptions {
  std::string name;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();  // rest position (m)
};

// A rigid instrument in unilateral frictional contact with the tissue surface (contact.h).
// Local frame: the origin is the tip (probe: sphere centre; shaft: centre of the tip hemisphere;
// tube: centre of the opening; grasper: centre of the jaws) and +z runs back along the
// instrument, away from the tissue it touches.
struct InstrumentOptions {
  enum class Type {
    Probe,    // sphere of `radius`
    Shaft,    // capsule: a cylinder of `radius` from the tip to `length` along +z, rounded ends
    Tube,     // aspiration tube: wall between `inner_radius` and `outer_radius` from the opening
              // to `length` along +z; `suction` acts on the tissue surface inside the lumen
    Grasper   // when `closed`, holds the surface nodes within `radius` of the tip where they are
  };
  struct Keyframe {  // a pose at time t (s); poses between keyframes are interpolated
    double t = 0;
    Eigen::Vector3d position = Eigen::Vector3d::Zero();             // m
    Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
    std::optional<bool> closed;  // grasper: closes or opens at this keyframe
  };
  std::string name;
  Type type = Type::Probe;
  bool enabled = true;          // false: out of the scene (touches and holds nothing)
  // m, tip; each coordinate within [-100, 100] (keyframes too): farther is a broken pose
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  // Sizes, in [1e-4, 0.05] m: the surface is sampled half a radius apart near an instrument, and
  // a 10 cm wide instrument would press most of a liver.
  double radius = 0.003;        // m: probe sphere, shaft, grasper hold radius
  double length = 0.05;         // m: shaft and tube, in [1e-4, 0.5]
  double inner_radius = 0.005;  // m: tube lumen
  double outer_radius = 0.0065; // m: tube wall outside, > inner_radius
  double suction = 0.0;         // Pa, tube: pressure below ambient in the lumen, in [0, 101325] (vacuum)
  bool closed = false;          // grasper
  std::vector<Keyframe> trajectory;  // empty: the pose stays where it is set; at most 10000 keyframes
};

constexpr int kMaxInstruments = 16;  // instruments in one model (InstrumentContact::add_instrument)
// Contact points of all instruments in one detection (InstrumentContact::detect): the Delassus
// operator of m points is a dense 3m x 3m matrix filled in O(m^2), 288 MB at this bound, and
// the nodes' compliance cache (NodeCompliance: up to twice the nodes in contact, 3 x 3 blocks
// between all of them) up to about 1.2 GB more on one factor. The
// aspiration tube pressing its cube makes 16; a wire of 0.1 mm lying 4 mm along the probe cube's
// face, 2,913.
constexpr int kMaxContacts = 2000;
// Surface samples one detection may test against the instruments (at most half an instrument's
// radius apart on the triangles near it): a wire of 0.1 mm hovering 5 mm above the probe cube
// with an alarm distance of 10 mm took 909,889 and 3.5 s before its contacts were counted.
constexpr int kMaxContactSamples = 100 * kMaxContacts;

// The contact solver (projected Gauss-Seidel on the Delassus operator, contact.h).
struct ContactOptions {
  double friction = 0.0;            // -, Coulomb coefficient between instruments and tissue, in [0, 10]
  double alarm_distance = 0.5e-3;   // m: surface nodes nearer than this to an instrument enter the contact problem, in [0, 0.01]
  double tolerance = 1e-7;          // m: largest penetration or stick slip accepted at convergence
  int max_iterations = 1000;        // Gauss-Seidel sweeps per contact solve, in [1, 1e6]
};

// How far to trust the registered targets (target_uncertainty.h): what the model does not know.
struct UncertaintyOptions {
  double patch_spacing = 0.03;     // m, in [1e-3, 1]: distance between the centres of the unknown force patches
  double force_ratio = 1.0;        // -, >= 0: unknown force per patch over the springs' typical force per patch
  double stiffness_log_sd = 0.35;  // -, >= 0: standard deviation of the log of the tissue's stiffness factor
};

// Non-rigid registration to intra-operative point clouds (registration.h). The cloud pulls the
// boundary through springs between each accepted point and its closest point on the surface.
struct RegistrationOptions {
  enum class Metric {
    PointToPlane,  // the spring acts along the surface normal at the closest point (slides freely)
    PointToPoint   // isotropic spring to the closest point
  };
  double stiffness = 3e5;          // N/m: total of the springs, shared by the accepted points by weight
  Metric metric = Metric::PointToPlane;
  double voxel_size = 5e-3;        // m: voxel-grid downsampling of the cloud (0: none), in [0, 0.1]
  int max_points = 4000;           // points kept after downsampling (evenly strided beyond it), in [1, 100000]
  double max_distance = 15e-3;     // m: points farther than this from the surface are outliers
  double trim_fraction = 0.1;      // -, in [0, 0.9): the farthest fraction of the rest is dropped too
  double huber_width = 2e-3;       // m: beyond this distance a point's weight falls as width/distance
  int correspondence_updates = 3;  // closest points recomputed and solved this many times per cloud, in [1, 100]
  int frame_updates = 100;         // of those, per call of register_cloud or refine (a frame), in [1, 100]: the
                                   // cloud's first ones in its own frame, the rest in the next refine() calls
  int newton_iterations = 1;       // per update (a real-time frame: the next cloud continues), in [1, 100]
  SolverOptions::Strategy strategy = SolverOptions::Strategy::ModifiedNewton;  // of those iterations
  bool rigid_alignment = false;    // PCL ICP of the first cloud to the surface, applied to all clouds
  // What a cloud must show before it acts, and how hard it may pull (registration.h).
  int min_points = 50;             // accepted points, >= 1: fewer and the cloud is refused
  double min_coverage = 0.02;      // -, in [0, 1]: share of the boundary area the accepted points cover
  double full_coverage = 0.2;      // -, in (0, 1]: the springs' total is `stiffness` from this coverage
                                   // on, and falls in proportion below it
  // Attachments the segmentation may not show (a ligament): regions of the surface the
  // registration holds at their rest position when the clouds call for it (registration.h).
  std::vector<Region> candidate_supports;
  double support_stiffness = 1e3;  // N/m, > 0: per surface node of a held candidate
  double support_gain = 0.15;      // -, in (0, 1): share of the cloud springs' patch pull a candidate must remove
  // The tissue's stiffness factor the clouds may call for (SurfaceRegistration::
  // estimate_tissue_stiffness): a factor on every Young's modulus of the scene, kept within
  // [min, max]; both 1: the scene's stiffness stands. A min of 1 takes the scene's stiffness
  // as the softest the patient's may be (doc/registration.md).
  double min_tissue_stiffness_factor = 1.0;  // -, in (0, 1]
  double max_tissue_stiffness_factor = 1.0;  // -, >= 1
  bool estimates_tissue_stiffness() const { return min_tissue_stiffness_factor < 1 || max_tissue_stiffness_factor > 1; }
  // Forces on the surface the camera does not see (the diaphragm, a retractor, a ligament's
  // reaction) that take the springs' systematic pull off the surface it sees
  // (SurfaceRegistration::estimate_hidden_loads); not with the stiffness estimate or candidate
  // supports (turn it off to use either). On by default: against the independent truth they
  // carry what the camera does not see (doc/registration.md#results).
  bool estimate_hidden_loads = true;
  double hidden_load_damping = 3.0;  // -, in [1e-6, 1e3]: Tikhonov weight on the loads, over the mean
                                     // diagonal of the fit's normal matrix
  UncertaintyOptions uncertainty;
};

// Empty string when valid, else a message naming the field at fault.
std::string validate(const ParenchymaOptions& o);
std::string validate(const CapsuleOptions& o);
// The scene files' word for a strategy ("modified_newton", ...), and the strategy of a word.
const char* strategy_word(SolverOptions::Strategy s);
std::optional<SolverOptions::Strategy> parse_strategy(const std::string& word);
std::string validate(const SolverOptions& o);
std::string validate(const Region& r);
std::string validate(const VesselOptions& o);  // field names prefixed with "vessels.<name>."
std::string validate(const InstrumentOptions& o);  // field names prefixed with "instruments.<name>."
std::string validate(const ContactOptions& o);
std::string validate(const RegistrationOptions& o);

}  // namespace liver_sim
