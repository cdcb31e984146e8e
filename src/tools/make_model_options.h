// make_model's command line: the options, their units and bounds, and --help's text
// (doc/patient_model.md lists the same).
#pragma once

#include <Eigen/Core>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "liver_sim/meshing/anatomy.h"

namespace liver_sim {

struct Vessel {
  std::string name, file;
};

enum class Resurface { Auto, Always, Never };

struct Options {
  std::string surface, label_map, label = "1", out, name = "liver", boundary_out;
  double unit = 1e-3;  // input unit -> m
  std::string unit_name = "mm";
  PatientFrame frame = PatientFrame::LPS;
  int elements = 10000;
  double size = 0;  // input unit
  double feature_angle = 40;
  double max_deviation = -1;  // input unit; < 0: 0.5 mm
  double max_hausdorff = -1;  // input unit; < 0: 1.5 mm
  double coarsen_within = -1;  // input unit; < 0: 0.7 of the Hausdorff bound
  double max_volume_change = 1;  // percent
  double merge_distance = 0;  // input unit
  bool largest_shell = false;
  Resurface resurface = Resurface::Auto;
  double voxel_size = -1;  // input unit; < 0: 1 mm
  double smoothing = -1;   // input unit; < 0: 1 mm
  double min_dihedral = 10;  // degrees
  std::vector<std::string> landmarks;
  std::vector<Eigen::Vector4d> spheres;  // input unit and frame
  std::string posture = "supine";
  std::vector<Vessel> vessels;
  double wall_ratio = 0.1;
  double snap_tolerance = -1;  // input unit; < 0: 1 mm
  bool quiet = false;
  double time_limit = 600;  // s
};

// The Hausdorff distance's target, m: --max-hausdorff, 1.5 mm by default.
inline double hausdorff_bound(const Options& o) { return o.max_hausdorff > 0 ? o.max_hausdorff * o.unit : 1.5e-3; }

// How far a re-surfaced boundary may be coarsened from its surface, m: --coarsen-within, else
// 0.7 of the Hausdorff bound; the rest of the bound is the sliver repair's.
inline double coarsening_bound(const Options& o) {
  return o.coarsen_within >= 0 ? o.coarsen_within * o.unit : 0.7 * hausdorff_bound(o);
}

// Thrown past the command line when a setting turns out impossible for the input (e.g. --size
// for a volume that would need too many tetrahedra): exit status 2, as a refused command line.
class CommandLineError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The command line into `o` (CLI11, tool_io.h): the exit status when make_model is to stop here
// (0 after --help, 2 after a refusal, named on standard error), else nothing: run.
std::optional<int> parse_args(int argc, char** argv, Options* o);

}  // namespace liver_sim
