// make_model's way from the input to a tetrahedral mesh: a surface repaired and meshed as it is,
// or re-surfaced from its enclosed volume when it cannot be (--resurface auto: holes, crossings,
// non-manifold parts, stair-steps that split it into many patches, a gmsh failure or a missed
// target on it); a label map always re-surfaced. Then the targets checked: the smallest dihedral
// angle and the element count here, the shape (Hausdorff distance, volume) once measured.
#pragma once

#include <chrono>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "liver_sim/geometry/mesh.h"
#include "liver_sim/geometry/mesh_quality.h"
#include "liver_sim/geometry/surface_mesh.h"
#include "liver_sim/meshing/resurface.h"
#include "liver_sim/meshing/sliver_repair.h"
#include "liver_sim/meshing/surface_deviation.h"
#include "liver_sim/meshing/surface_repair.h"
#include "liver_sim/meshing/volume_mesher.h"
#include "make_model_options.h"

namespace liver_sim {

// The phases' wall time: seconds since the last lap.
class Stopwatch {
 public:
  double lap() {
    const auto now = std::chrono::steady_clock::now();
    const double s = std::chrono::duration<double>(now - last_).count();
    last_ = now;
    return s;
  }

 private:
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

struct ModelMesh {
  std::string input_name;          // the --surface or --label-map file
  Eigen::Index input_triangles = 0;  // 0 for a label map
  SurfaceMesh input;               // the surface as read (LPS, m); empty for a label map
  int label = 0;                   // the label taken from a label map
  SurfaceMesh surface;             // the surface meshed (repaired, or re-surfaced)
  SurfaceRepairs repairs;
  bool resurfaced = false;
  std::string resurface_reason;    // why (the defect, gmsh's message, the target missed)
  ResurfaceReport resurfacing;
  TetMesh mesh;
  VolumeMeshReport mesh_report;
  SliverRepairReport slivers;      // when gmsh's mesh missed --min-dihedral
  TetQuality quality;
  std::string missed;              // the mesh's targets missed and why; empty when met
  std::vector<std::pair<std::string, double>> times;  // stage, s
};

// The element count's target: within 15% of --elements.
constexpr double kCountTolerance = 0.15;


// Throws MeshError (bad input, with the file and the defect) or CommandLineError.
ModelMesh make_model_mesh(const Options& o, const std::function<void(const std::string&)>& say);

// The shape's targets: the Hausdorff distance between the mesh's boundary and the surface it
// meshed (--max-hausdorff), and their volumes (--max-volume-change). Each missed one with its
// value, the bound and by how much ("; " between them); empty when both are met.
std::string missed_shape_targets(const Options& o, const SurfaceDeviation& distance, double surface_volume,
                                 double mesh_volume);

}  // namespace liver_sim
