// A patient's liver model from a segmented surface (and vessel centrelines): repairs and checks
// the surface, meshes its volume with gmsh, reports the mesh quality and the shape kept
// (Hausdorff distance), writes the mesh, the vessel trees and a scene file the simulator and the
// node run. doc/patient_model.md explains the options; `make_model --help` lists them.
// Progress goes to standard error, a JSON report to standard output. Exit status: 0 done, 1 bad
// input (one line naming the file and the defect), 2 bad command line.
#include <unistd.h>

#include <csignal>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "json_text.h"
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

const char* kUsage =
    "usage: make_model --surface FILE --out DIR [options]\n"
    "Turns a segmented liver surface into a tetrahedral model and a scene file (doc/patient_model.md).\n"
    "Lengths on this command line are in the input's unit (--unit) and frame (--input-frame); the\n"
    "outputs are in metres in the model frame, the patient's LPS (+x left, +y posterior, +z superior).\n"
    "\n"
    "  --surface FILE        closed liver surface: .stl (ASCII or binary), .obj, .ply (ASCII or binary),\n"
    "                        .vtk (legacy polydata, ASCII or binary)\n"
    "  --out DIR             output folder (created if missing): NAME.msh (Gmsh 2.2), NAME.yaml (scene),\n"
    "                        NAME_<vessel>.vtk (vessel trees)\n"
    "  --name NAME           base name of the outputs (default liver)\n"
    "  --unit mm|cm|m        length unit of the input files (default mm)\n"
    "  --input-frame LPS|RAS patient frame of the input files (default LPS: DICOM, ITK, 3D Slicer >= 4.11;\n"
    "                        RAS: older 3D Slicer files); RAS is turned to LPS (x and y negated)\n"
    "  --elements N          target number of tetrahedra, in [500, 200000] (default 10000; met within ~15%)\n"
    "  --size L              target element edge length, > 0 (input unit), instead of --elements; at most\n"
    "                        1,000,000 tetrahedra\n"
    "  --feature-angle DEG   surface creases sharper than this stay edges of the mesh, in [10, 90] degrees\n"
    "                        (default 40)\n"
    "  --max-deviation D     curved parts get shorter edges (down to a quarter of the size) so that the\n"
    "                        mesh stays within D of the surface, > 0 (input unit; default 0.5 mm)\n"
    "  --merge-distance D    vertices closer than D are merged, >= 0 (input unit; default 0: 1e-6 of the\n"
    "                        surface's bounding-box diagonal)\n"
    "  --largest-shell       several disconnected shells: keep the largest (by volume) instead of refusing\n"
    "  --fixed LANDMARK      attachment by anatomy (repeatable): bare_area, a sphere of 0.15 times the\n"
    "                        liver's largest extent on its most posterior-superior point (the default when\n"
    "                        neither --fixed nor --fixed-sphere is given)\n"
    "  --fixed-sphere X,Y,Z,R  attachment: nodes within R of (X, Y, Z), input unit and frame, R > 0 (repeatable)\n"
    "  --posture supine|prone|upright  direction of gravity, 9.81 m/s^2 (default supine: toward the\n"
    "                        patient's back, +y; prone -y; upright -z)\n"
    "  --vessels NAME=FILE   vessel centrelines (repeatable), input unit and frame: legacy VTK polydata\n"
    "                        polylines with `radius` or VMTK's `MaximumInscribedSphereRadius`, or the\n"
    "                        package's .yaml trees; NAME: letters, digits, _ and -\n"
    "  --wall-ratio R        vessel wall thickness as a fraction of the radius where the file has no\n"
    "                        `wall_thickness`, in (0, 1] (default 0.1)\n"
    "  --snap-tolerance D    vessel nodes at most D outside the mesh are moved onto it, >= 0 (input unit;\n"
    "                        default 1 mm)\n"
    "  --boundary-out FILE   also write the model's boundary surface (format by extension) in the input's\n"
    "                        unit and frame, to overlay on the segmentation\n"
    "  --time-limit S        wall time the run may take, in [1, 86400] s (default 600): past it make_model\n"
    "                        stops with exit status 1 and says so (a mesher that does not finish)\n"
    "  --quiet               no progress on standard error\n"
    "  --help                this text\n"
    "Exit status: 0 done, 1 bad input (one line naming the file and the defect), 2 bad command line.\n";

struct Vessel {
  std::string name, file;
};

struct Options {
  std::string surface, out, name = "liver", boundary_out;
  double unit = 1e-3;  // input unit -> m
  std::string unit_name = "mm";
  PatientFrame frame = PatientFrame::LPS;
  int elements = 10000;
  double size = 0;  // input unit
  double feature_angle = 40;
  double max_deviation = -1;  // input unit; < 0: 0.5 mm
  double merge_distance = 0;  // input unit
  bool largest_shell = false;
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

double parse_number(const std::string& option, const std::string& text, double lo, double hi, bool lo_open = false) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(v) || v < lo || v > hi ||
      (lo_open && v == lo))
    throw CommandLineError(option + ": expected a number in " + (lo_open ? "(" : "[") + std::to_string(lo) + ", " +
                           std::to_string(hi) + "], got '" + text + "'");
  return v;
}

std::vector<double> parse_list(const std::string& option, const std::string& text, size_t n) {
  std::vector<double> v;
  std::stringstream s(text);
  std::string item;
  while (std::getline(s, item, ',')) v.push_back(parse_number(option, item, -1e9, 1e9));
  if (v.size() != n) throw CommandLineError(option + ": expected " + std::to_string(n) + " comma-separated numbers");
  return v;
}

Options parse_args(int argc, char** argv) {
  Options o;
  bool sized = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw CommandLineError(a + ": missing value");
      return argv[++i];
    };
    if (a == "--surface") {
      o.surface = value();
    } else if (a == "--out") {
      o.out = value();
    } else if (a == "--name") {
      o.name = value();
      if (o.name.empty() || o.name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") != std::string::npos)
        throw CommandLineError("--name: letters, digits, _ and - only");
    } else if (a == "--unit") {
      o.unit_name = value();
      if (o.unit_name == "mm") o.unit = 1e-3;
      else if (o.unit_name == "cm") o.unit = 1e-2;
      else if (o.unit_name == "m") o.unit = 1.0;
      else throw CommandLineError("--unit: expected mm, cm or m, got '" + o.unit_name + "'");
    } else if (a == "--input-frame") {
      const std::string f = value();
      if (f == "LPS") o.frame = PatientFrame::LPS;
      else if (f == "RAS") o.frame = PatientFrame::RAS;
      else throw CommandLineError("--input-frame: expected LPS or RAS, got '" + f + "'");
    } else if (a == "--elements") {
      o.elements = static_cast<int>(parse_number(a, value(), 500, 200000));
      sized = true;
    } else if (a == "--size") {
      o.size = parse_number(a, value(), 0, 1e9, true);
    } else if (a == "--feature-angle") {
      o.feature_angle = parse_number(a, value(), 10, 90);
    } else if (a == "--max-deviation") {
      o.max_deviation = parse_number(a, value(), 0, 1e9, true);
    } else if (a == "--merge-distance") {
      o.merge_distance = parse_number(a, value(), 0, 1e9);
    } else if (a == "--largest-shell") {
      o.largest_shell = true;
    } else if (a == "--fixed") {
      o.landmarks.push_back(value());
      if (o.landmarks.back() != "bare_area")
        throw CommandLineError("--fixed: unknown landmark '" + o.landmarks.back() + "' (known: bare_area)");
    } else if (a == "--fixed-sphere") {
      const std::vector<double> v = parse_list(a, value(), 4);
      if (!(v[3] > 0)) throw CommandLineError("--fixed-sphere: the radius must be > 0");
      o.spheres.emplace_back(v[0], v[1], v[2], v[3]);
    } else if (a == "--posture") {
      o.posture = value();
      if (o.posture != "supine" && o.posture != "prone" && o.posture != "upright")
        throw CommandLineError("--posture: expected supine, prone or upright, got '" + o.posture + "'");
    } else if (a == "--vessels") {
      const std::string v = value();
      const size_t eq = v.find('=');
      Vessel vessel{v.substr(0, eq == std::string::npos ? 0 : eq), eq == std::string::npos ? "" : v.substr(eq + 1)};
      if (vessel.name.empty() || vessel.file.empty() ||
          vessel.name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") != std::string::npos)
        throw CommandLineError("--vessels: expected NAME=FILE with a NAME of letters, digits, _ and -, got '" + v + "'");
      for (const Vessel& other : o.vessels)
        if (other.name == vessel.name) throw CommandLineError("--vessels: the name '" + vessel.name + "' is given twice");
      o.vessels.push_back(vessel);
    } else if (a == "--wall-ratio") {
      o.wall_ratio = parse_number(a, value(), 0, 1, true);
    } else if (a == "--snap-tolerance") {
      o.snap_tolerance = parse_number(a, value(), 0, 1e9);
    } else if (a == "--boundary-out") {
      o.boundary_out = value();
    } else if (a == "--time-limit") {
      o.time_limit = parse_number(a, value(), 1, 86400);
    } else if (a == "--quiet") {
      o.quiet = true;
    } else {
      throw CommandLineError("unknown option '" + a + "'");
    }
  }
  if (o.surface.empty() || o.out.empty()) throw CommandLineError("--surface and --out are required");
  if (sized && o.size > 0) throw CommandLineError("give --elements or --size, not both");
  return o;
}

std::string vec(const Eigen::Vector3d& v) {
  std::ostringstream s;
  s << std::setprecision(std::numeric_limits<double>::max_digits10) << "[" << v[0] << ", " << v[1] << ", " << v[2] << "]";
  return s.str();
}

// Seconds since the last call.
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

int run(const Options& o) {
  auto say = [&](const std::string& s) {
    if (!o.quiet) std::cerr << "make_model: " << s << "\n";
  };
  Stopwatch clock;
  std::ostringstream times;

  say("reading " + o.surface);
  SurfaceMesh input = read_surface(o.surface, o.unit);
  input.V = to_lps(input.V, o.frame);
  const Eigen::Index input_triangles = input.F.rows();
  times << "\"read\": " << clock.lap();

  say("checking and repairing " + std::to_string(input_triangles) + " triangles");
  SurfaceRepairOptions repair_options;
  repair_options.merge_distance = o.merge_distance * o.unit;
  repair_options.keep_largest_shell = o.largest_shell;
  SurfaceRepairs repairs;
  const SurfaceMesh surface = repair_surface(input, o.surface, repair_options, &repairs);
  for (const std::string& note : repairs.notes) say(note);
  const Eigen::Vector3d extent = surface.V.colwise().maxCoeff() - surface.V.colwise().minCoeff();
  // A liver measures 10-30 cm: far outside 1 cm - 1 m the unit is wrong.
  if (extent.maxCoeff() > 1.0 || extent.maxCoeff() < 0.01) {
    std::ostringstream m;
    m << o.surface << ": the surface spans " << extent.maxCoeff() << " m with --unit " << o.unit_name
      << " (a liver spans 0.1-0.3 m; outside 0.01-1 m the unit is wrong)";
    throw MeshError(m.str());
  }
  const double volume = enclosed_volume(surface);
  times << ", \"repair\": " << clock.lap();

  VolumeMeshOptions mesh_options;
  mesh_options.element_size = o.size * o.unit;
  mesh_options.target_elements = o.elements;
  mesh_options.feature_angle = o.feature_angle;
  mesh_options.max_deviation = o.max_deviation > 0 ? o.max_deviation * o.unit : 0.5e-3;
  mesh_options.progress = say;
  if (o.size > 0 && 4.9 * volume / std::pow(mesh_options.element_size, 3) > 1e6)
    throw CommandLineError("--size: " + std::to_string(o.size) + " " + o.unit_name +
                           " would make over 1,000,000 tetrahedra");
  VolumeMeshReport mesh_report;
  const TetMesh mesh = mesh_volume(surface, o.surface, mesh_options, &mesh_report);
  times << ", \"mesh\": " << clock.lap();

  say("measuring quality and shape (" + std::to_string(mesh.T.rows()) + " tetrahedra)");
  const TetQuality quality = tet_quality(mesh);
  const SurfaceMesh boundary{mesh.V, boundary_triangles(mesh.T)};
  const SurfaceDeviation distance = surface_deviation(surface, boundary, 0.1 * mesh_report.element_size);
  times << ", \"quality_and_distance\": " << clock.lap();

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
    fixed_comment.push_back(landmark + ": the most posterior-superior point of the surface, 0.15 x its extent");
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
    fixed_comment.push_back("bare area (default): the most posterior-superior point of the surface, 0.15 x its extent");
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
    scene << "# Patient liver model by make_model from " << o.surface << " (" << input_triangles << " triangles, "
          << o.unit_name << ", " << (o.frame == PatientFrame::LPS ? "LPS" : "RAS") << "); doc/patient_model.md.\n"
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
  times << ", \"scene_check\": " << clock.lap();

  std::ostringstream js;
  js << std::setprecision(9) << "{\n"
     << "  \"surface\": " << json_string(o.surface) << ",\n"
     << "  \"scene\": " << json_string((dir / scene_file).string()) << ",\n"
     << "  \"input_triangles\": " << input_triangles << ",\n"
     << "  \"repairs\": {\"merged_vertices\": " << repairs.merged_vertices
     << ", \"unused_vertices\": " << repairs.unused_vertices
     << ", \"collapsed_triangles\": " << repairs.collapsed_triangles
     << ", \"duplicate_triangles\": " << repairs.duplicate_triangles
     << ", \"reoriented_triangles\": " << repairs.reoriented_triangles
     << ", \"inside_out\": " << (repairs.inside_out ? "true" : "false")
     << ", \"dropped_shells\": " << repairs.dropped_shells << "},\n"
     << "  \"surface_triangles\": " << surface.F.rows() << ",\n"
     << "  \"volume_m3\": {\"surface\": " << volume << ", \"mesh\": " << enclosed_volume(boundary) << "},\n"
     << "  \"nodes\": " << mesh.V.rows() << ",\n"
     << "  \"tetrahedra\": " << mesh.T.rows() << ",\n"
     << "  \"boundary_triangles\": " << boundary.F.rows() << ",\n"
     << "  \"element_size\": " << mesh_report.element_size << ",\n"
     << "  \"meshing_passes\": " << mesh_report.passes << ",\n"
     << "  \"curvature_sizing\": " << (mesh_report.curvature_sizing ? "true" : "false") << ",\n"
     << "  \"quality\": {\"min_dihedral_deg\": " << quality.min_dihedral_deg
     << ", \"max_dihedral_deg\": " << quality.max_dihedral_deg
     << ", \"radius_ratio\": {\"min\": " << quality.min_radius_ratio << ", \"mean\": " << quality.mean_radius_ratio
     << "}},\n"
     << "  \"hausdorff_m\": {\"surface_to_mesh\": {\"max\": " << distance.a_to_b.max << ", \"mean\": " << distance.a_to_b.mean
     << "}, \"mesh_to_surface\": {\"max\": " << distance.b_to_a.max << ", \"mean\": " << distance.b_to_a.mean
     << "}, \"hausdorff\": " << distance.hausdorff() << "},\n"
     << "  \"fixed_nodes\": " << fixed_nodes << ",\n"
     << "  \"vessels\": " << o.vessels.size() << ",\n"
     << "  \"time_s\": {" << times.str() << "}\n"
     << "}\n";
  std::cout << js.str();
  say("wrote " + (dir / mesh_file).string() + " and " + (dir / scene_file).string());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]) == "--help") {
      std::cout << kUsage;
      return 0;
    }
  Options options;
  try {
    options = parse_args(argc, argv);
  } catch (const CommandLineError& e) {
    std::cerr << "make_model: " << e.what() << "\n" << kUsage;
    return 2;
  }
  // A watchdog: gmsh has been seen to recurse without end on rare surfaces; the run then ends
  // with a message instead of hanging its caller.
  std::signal(SIGALRM, [](int) {
    static const char text[] = "make_model: the time limit (--time-limit) ran out; the mesher did not finish\n";
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
