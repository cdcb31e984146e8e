#include "make_model_options.h"

#include <cmath>
#include <cstdlib>
#include <sstream>

namespace liver_sim {

const char* const kMakeModelUsage =
    "usage: make_model (--surface FILE | --label-map FILE [--label L]) --out DIR [options]\n"
    "Turns a segmented liver (a surface or a label map) into a tetrahedral model and a scene file\n"
    "(doc/patient_model.md).\n"
    "Lengths on this command line are in the input's unit (--unit) and frame (--input-frame); the\n"
    "outputs are in metres in the model frame, the patient's LPS (+x left, +y posterior, +z superior).\n"
    "\n"
    "  --surface FILE        closed liver surface: .stl (ASCII or binary), .obj, .ply (ASCII or binary),\n"
    "                        .vtk (legacy polydata, ASCII or binary)\n"
    "  --label-map FILE      instead of --surface: a label map, .nii, .nii.gz (NIfTI-1), .nrrd, .seg.nrrd;\n"
    "                        its own spacing, origin, direction and unit (LPS; NIfTI's RAS converted)\n"
    "  --label L             the liver's label in --label-map: a number, or a segment name of a .seg.nrrd\n"
    "                        (default 1)\n"
    "  --resurface auto|always|never  rebuild the surface from a voxel volume (ray votes, Gaussian\n"
    "                        smoothing, contour): auto (default) when the surface has holes, crossings or\n"
    "                        non-manifold parts, splits into many patches (stair-steps, noise), or gmsh\n"
    "                        fails or misses the quality on it; a label map is always re-surfaced\n"
    "  --voxel-size V        grid step for re-surfacing a surface, > 0 (input unit; default 1 mm)\n"
    "  --smoothing S         width (standard deviation) of the smoothing when re-surfacing, > 0 (input\n"
    "                        unit; default 1 mm): stair-steps and noise finer than this go\n"
    "  --min-dihedral DEG    quality every tetrahedron must reach, in [1, 30] degrees (default 10)\n"
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
    "Exit status: 0 done, 1 bad input (one line naming the file and the defect), 2 bad command line,\n"
    "3 the model is written but misses --min-dihedral or the element count (within 15% of --elements):\n"
    "the report's \"targets\" says which and why.\n";

namespace {

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

}  // namespace

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
    } else if (a == "--label-map") {
      o.label_map = value();
    } else if (a == "--label") {
      o.label = value();
      if (o.label.empty()) throw CommandLineError("--label: a number or a segment name");
    } else if (a == "--resurface") {
      const std::string r = value();
      if (r == "auto") o.resurface = Resurface::Auto;
      else if (r == "always") o.resurface = Resurface::Always;
      else if (r == "never") o.resurface = Resurface::Never;
      else throw CommandLineError("--resurface: expected auto, always or never, got '" + r + "'");
    } else if (a == "--voxel-size") {
      o.voxel_size = parse_number(a, value(), 0, 1e9, true);
    } else if (a == "--smoothing") {
      o.smoothing = parse_number(a, value(), 0, 1e9, true);
    } else if (a == "--min-dihedral") {
      o.min_dihedral = parse_number(a, value(), 1, 30);
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
  if (o.surface.empty() == o.label_map.empty()) throw CommandLineError("give one of --surface and --label-map");
  if (o.out.empty()) throw CommandLineError("--out is required");
  if (!o.label_map.empty() && o.resurface == Resurface::Never)
    throw CommandLineError("--resurface never: a label map is always re-surfaced");
  if (sized && o.size > 0) throw CommandLineError("give --elements or --size, not both");
  return o;
}

}  // namespace liver_sim
