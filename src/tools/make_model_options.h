// make_model's command line: the options, their units and bounds, and --help's text
// (doc/patient_model.md lists the same).
#pragma once

#include <Eigen/Core>
#include <stdexcept>
#include <string>
#include <vector>

#include "liver_sim/meshing/anatomy.h"

namespace liver_sim {

extern const char* const kMakeModelUsage;

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

class CommandLineError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Throws CommandLineError naming the option at fault.
Options parse_args(int argc, char** argv);

}  // namespace liver_sim
