// A patient's liver model from a segmented surface or label map (and vessel centrelines): repairs
// or re-surfaces the input (make_model_mesh.h), meshes its volume with gmsh, reports the mesh
// quality and the shape kept (Hausdorff distances), writes the mesh, the vessel trees and a scene
// file the simulator and the node run. doc/patient_model.md explains the options; `make_model
// --help` lists them. Progress goes to standard error, a JSON report to standard output. Exit
// status: 0 done, 1 bad input (one line naming the file and the defect), 2 bad command line, 3
// written but a target (smallest dihedral angle, element count, Hausdorff distance, volume) missed.
#include <unistd.h>

#include <csignal>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "make_model_mesh.h"
#include "make_model_options.h"
#include "tool_io.h"
#include "liver_sim/geometry/mesh_quality.h"
#include "liver_sim/geometry/vessel_tree.h"
#include "liver_sim/io/mesh_io.h"
#include "liver_sim/io/surface_io.h"
#include "liver_sim/io/vessel_io.h"
#include "liver_sim/meshing/anatomy.h"
#include "liver_sim/meshing/surface_deviation.h"
#include "liver_sim/meshing/surface_repair.h"
#include "liver_sim/meshing/volume_mesher.h"
#include "liver_sim/simulation/liver_model.h"

namespace {

using namespace liver_sim;
using Json = nlohmann::ordered_json;

std::string vec(const Eigen::Vector3d& v) {
  std::ostringstream s;
  s << std::setprecision(std::numeric_limits<double>::max_digits10) << "[" << v[0] << ", " << v[1] << ", " << v[2] << "]";
  return s.str();
}

int run(const Options& o) {
  auto say = [&](const std::string& s) {
    if (!o.quiet) std::cerr << "make_model: " << s << "\n";
  };
  Stopwatch clock;
  const ModelMesh m = make_model_mesh(o, say);
  const SurfaceMesh& surface = m.surface;
  const TetMesh& mesh = m.mesh;
  Json times = Json::object();
  for (const auto& [stage, seconds] : m.times) times[stage] = seconds;
  clock.lap();

  say("measuring quality and shape (" + std::to_string(mesh.T.rows()) + " tetrahedra)");
  const TetQuality& quality = m.quality;
  const SurfaceMesh boundary{mesh.V, boundary_triangles(mesh.T)};
  const SurfaceDeviation distance = surface_deviation(surface, boundary, 0.1 * m.mesh_report.element_size);
  // A re-surfaced input: how far the new surface and the mesh lie from the surface as given.
  std::optional<SurfaceDeviation> from_input, mesh_from_input;
  if (m.resurfaced && m.input.F.rows() > 0) {
    const double spacing = std::min(0.1 * m.mesh_report.element_size, m.resurfacing.voxel_size);
    from_input = surface_deviation(m.input, surface, spacing);
    mesh_from_input = surface_deviation(m.input, boundary, spacing);
  }
  times["quality_and_distance"] = clock.lap();

  std::filesystem::create_directories(o.out);
  const std::filesystem::path dir(o.out);
  const std::string mesh_file = o.name + ".msh", scene_file = o.name + ".yaml";
  write_gmsh22((dir / mesh_file).string(), mesh);
  if (!o.boundary_out.empty()) {
    SurfaceMesh in_input_units{to_lps(boundary.V, o.frame) / o.unit, boundary.F};  // LPS <-> RAS is its own inverse
    write_surface(o.boundary_out, in_input_units);
  }

  std::vector<Region> fixed;
  std::vector<std::string> fixed_comment;
  for (const std::string& landmark : o.landmarks) {
    fixed.push_back(bare_area(surface));
    fixed_comment.push_back(landmark + ": the most posterior-superior point of the surface, 0.25 x its extent");
  }
  for (const Eigen::Vector4d& s : o.spheres) {
    Region r;
    r.kind = Region::Kind::Sphere;
    r.center = to_lps(s.head<3>().transpose() * o.unit, o.frame).row(0).transpose();
    r.radius = s[3] * o.unit;
    fixed.push_back(r);
    fixed_comment.push_back("--fixed-sphere " + std::to_string(s[0]) + "," + std::to_string(s[1]) + "," +
                            std::to_string(s[2]) + "," + std::to_string(s[3]) + " " + o.unit_name);
  }
  if (fixed.empty()) {
    fixed.push_back(bare_area(surface));
    fixed_comment.push_back("bare area (default): the most posterior-superior point of the surface, 0.25 x its extent");
  }

  const double snap = o.snap_tolerance >= 0 ? o.snap_tolerance * o.unit : 1e-3;
  std::vector<std::string> vessel_files;
  for (const Vessel& v : o.vessels) {
    say("reading vessels " + v.name + " from " + v.file);
    VesselTree tree = read_vessel_tree(v.file, o.unit, o.wall_ratio);
    tree.points = to_lps(tree.points, o.frame);
    vessel_files.push_back(o.name + "_" + v.name + ".vtk");
    write_vessel_vtk((dir / vessel_files.back()).string(), tree, v.name + " vessel tree (m, LPS) from " + v.file);
  }

  const char* gravity = o.posture == "supine" ? "[0, 9.81, 0]" : o.posture == "prone" ? "[0, -9.81, 0]" : "[0, 0, -9.81]";
  {
    std::ofstream scene((dir / scene_file).string());
    scene << std::setprecision(std::numeric_limits<double>::max_digits10);
    scene << "# Patient liver model by make_model from " << m.input_name;
    if (o.label_map.empty())
      scene << " (" << m.input_triangles << " triangles, " << o.unit_name << ", "
            << (o.frame == PatientFrame::LPS ? "LPS" : "RAS") << (m.resurfaced ? ", re-surfaced" : "") << ")";
    else
      scene << " (label " << m.label << ")";
    scene << "; doc/patient_model.md.\n"
          << "# Model frame: the patient's LPS (+x left, +y posterior, +z superior), metres. " << mesh.T.rows()
          << " tetrahedra.\n"
          << "# Parameters: the in-vivo fit of the reference model, as config/scenes/liver_phantom.yaml.\n"
          << "mesh: {file: " << mesh_file << "}\n"
          << "parenchyma: {young_modulus: 30000, poisson_ratio: 0.45, density: 1060, rotation: polar}   # Pa, -, kg/m^3\n"
          << "capsule: {enabled: true, young_modulus: 3.0e6, thickness: 93.0e-6, poisson_ratio: 0.45}   # Pa, m, -\n";
    if (!o.vessels.empty()) scene << "vessels:\n";
    for (size_t i = 0; i < o.vessels.size(); ++i)
      scene << "  - {name: " << o.vessels[i].name << ", file: " << vessel_files[i]
            << ", young_modulus: 0.62e6, poisson_ratio: 0.45, snap_tolerance: " << snap << "}   # Pa, -, m\n";
    scene << "fixed:\n";
    for (size_t i = 0; i < fixed.size(); ++i)
      scene << "  - sphere: {center: " << vec(fixed[i].center) << ", radius: " << fixed[i].radius << "}   # "
            << fixed_comment[i] << "\n";
    scene << "loads:\n  - {type: gravity, acceleration: " << gravity << "}   # m/s^2, " << o.posture << "\n"
          << "solver:\n  mode: static\n  steps: 1\n  dt: 0.0333                # s, dynamic mode (the node at ~30 Hz)\n"
          << "  predictor: constant_acceleration\n  max_iterations: 50\n  tolerance: 1.0e-8\n"
          << "  rayleigh_mass: 0.0        # 1/s\n  rayleigh_stiffness: 0.05  # s\n";
    if (!scene) throw MeshError((dir / scene_file).string() + ": write failed");
  }

  // The scene must load as the simulator and the node load it: the attachments select nodes,
  // the vessel nodes lie inside the mesh (or within the snap tolerance).
  say("loading the scene as the simulator does");
  const Scene scene = load_scene((dir / scene_file).string());
  int fixed_nodes = 0;
  try {
    const LiverModel model(load_scene_mesh(scene), scene);
    for (const Region& r : scene.fixed)
      for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) fixed_nodes += r.contains(mesh.V.row(i).transpose());
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error((dir / scene_file).string() + ": " + e.what());
  }
  times["scene_check"] = clock.lap();

  auto deviation = [](const SurfaceDeviation& d) {
    return Json{{"a_to_b", {{"max", d.a_to_b.max}, {"mean", d.a_to_b.mean}}},
                      {"b_to_a", {{"max", d.b_to_a.max}, {"mean", d.b_to_a.mean}}},
                      {"hausdorff", d.hausdorff()}};
  };
  Json resurfacing = nullptr;
  if (m.resurfaced) {
    const ResurfaceReport& rr = m.resurfacing;
    resurfacing = {{"reason", m.resurface_reason},
                   {"voxel_size_m", rr.voxel_size},
                   {"smoothing_m", o.smoothing > 0 ? o.smoothing * o.unit : 1e-3},
                   {"inside_voxels", rr.inside_voxels},
                   {"disputed_voxels", rr.disputed_voxels},
                   {"pieces", rr.pieces},
                   {"dropped_voxels", rr.dropped_voxels},
                   {"filled_voxels", rr.filled_voxels},
                   {"triangles", rr.triangles}};
    if (from_input) {  // a: the input surface, b: the new surface (or the mesh's boundary)
      resurfacing["input_to_new_surface_m"] = deviation(*from_input);
      resurfacing["input_to_mesh_m"] = deviation(*mesh_from_input);
    }
  }
  const double surface_volume = enclosed_volume(surface), mesh_volume = enclosed_volume(boundary);
  Json js;
  js[o.label_map.empty() ? "surface" : "label_map"] = m.input_name;
  js["scene"] = (dir / scene_file).string();
  js["input_triangles"] = m.input_triangles;
  js["repairs"] = {{"merged_vertices", m.repairs.merged_vertices},
                   {"unused_vertices", m.repairs.unused_vertices},
                   {"collapsed_triangles", m.repairs.collapsed_triangles},
                   {"duplicate_triangles", m.repairs.duplicate_triangles},
                   {"reoriented_triangles", m.repairs.reoriented_triangles},
                   {"inside_out", m.repairs.inside_out},
                   {"dropped_shells", m.repairs.dropped_shells}};
  js["surface_triangles"] = surface.F.rows();
  js["resurfacing"] = resurfacing;
  js["volume_m3"] = {{"input", m.input.F.rows() > 0 ? Json(enclosed_volume(m.input)) : Json(nullptr)},
                     {"surface", surface_volume},
                     {"mesh", mesh_volume}};
  js["nodes"] = mesh.V.rows();
  js["tetrahedra"] = mesh.T.rows();
  js["boundary_triangles"] = boundary.F.rows();
  js["element_size"] = m.mesh_report.element_size;
  js["meshing_passes"] = m.mesh_report.passes;
  js["curvature_sizing"] = m.mesh_report.curvature_sizing;
  const bool slivers = m.slivers.peeled + m.slivers.moved_nodes > 0;
  js["slivers"] = {{"peeled", m.slivers.peeled},
                   {"moved_nodes", m.slivers.moved_nodes},
                   {"min_dihedral_before_deg", slivers ? Json(m.slivers.before_deg) : Json(nullptr)}};
  js["quality"] = {{"min_dihedral_deg", quality.min_dihedral_deg},
                   {"max_dihedral_deg", quality.max_dihedral_deg},
                   {"radius_ratio", {{"min", quality.min_radius_ratio}, {"mean", quality.mean_radius_ratio}}}};
  js["hausdorff_m"] = {{"surface_to_mesh", {{"max", distance.a_to_b.max}, {"mean", distance.a_to_b.mean}}},
                       {"mesh_to_surface", {{"max", distance.b_to_a.max}, {"mean", distance.b_to_a.mean}}},
                       {"hausdorff", distance.hausdorff()}};
  js["fixed_nodes"] = fixed_nodes;
  js["vessels"] = o.vessels.size();
  std::string missed = m.missed;
  if (const std::string shape = missed_shape_targets(o, distance, surface_volume, mesh_volume); !shape.empty())
    missed += (missed.empty() ? "" : "; ") + shape;
  js["targets"] = {{"min_dihedral_deg", o.min_dihedral},
                   {"tetrahedra", o.size > 0 ? Json(nullptr) : Json(o.elements)},
                   {"tetrahedra_tolerance", kCountTolerance},
                   {"hausdorff_m", hausdorff_bound(o)},
                   {"volume_change_percent", o.max_volume_change},
                   {"met", missed.empty()},
                   {"missed", missed}};
  js["time_s"] = times;
  tool::print_json(std::cout, js);
  say("wrote " + (dir / mesh_file).string() + " and " + (dir / scene_file).string());
  if (!missed.empty()) {
    std::cerr << "make_model: " << m.input_name << ": the model is written but misses its targets: " << missed << "\n";
    return 3;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options options;
  if (const std::optional<int> status = parse_args(argc, argv, &options)) return *status;
  // A watchdog over the whole run (each gmsh session has its own budget, volume_mesher.h): past
  // it the run ends with a message instead of hanging its caller.
  std::signal(SIGALRM, [](int) {
    static const char text[] = "make_model: the time limit (--time-limit) ran out before the model was made\n";
    [[maybe_unused]] const ssize_t n = write(STDERR_FILENO, text, sizeof(text) - 1);
    _exit(1);
  });
  alarm(static_cast<unsigned>(std::ceil(options.time_limit)));
  try {
    return run(options);
  } catch (const CommandLineError& e) {
    std::cerr << "make_model: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "make_model: " << e.what() << "\n";
    return 1;
  }
}
