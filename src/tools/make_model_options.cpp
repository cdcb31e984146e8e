#include "make_model_options.h"

#include <sstream>

#include "tool_io.h"

namespace liver_sim {
namespace {

const char* const kUsage =
    "usage: make_model (--surface FILE | --label-map FILE [--label L]) --out DIR [options]\n";
const char* const kDescription =
    "Turns a segmented liver (a surface or a label map) into a tetrahedral model and a scene file\n"
    "(doc/patient_model.md).\n"
    "Lengths on this command line are in the input's unit (--unit) and frame (--input-frame); the\n"
    "outputs are in metres in the model frame, the patient's LPS (+x left, +y posterior, +z superior).";
const char* const kExitStatus =
    "Exit status: 0 done, 1 bad input (one line naming the file and the defect), 2 bad command line,\n"
    "3 the model is written but misses --min-dihedral or the element count (within 15% of --elements):\n"
    "the report's \"targets\" says which and why.";

bool is_name(const std::string& s) {
  return !s.empty() &&
         s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") == std::string::npos;
}

// "X,Y,Z,R": four finite numbers, R > 0.
CLI::Validator sphere_text() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        std::stringstream s(text);
        std::string item;
        int n = 0;
        double last = 0;
        while (std::getline(s, item, ',')) {
          char* end = nullptr;
          last = std::strtod(item.c_str(), &end);
          if (item.empty() || *end != '\0' || !std::isfinite(last)) return "'" + item + "' is not a finite number";
          ++n;
        }
        if (n != 4) return "expected X,Y,Z,R (four comma-separated numbers), got '" + text + "'";
        return last > 0 ? "" : "the radius must be > 0";
      },
      "X,Y,Z,R");
}

Eigen::Vector4d parse_sphere(const std::string& text) {
  Eigen::Vector4d v;
  std::stringstream s(text);
  std::string item;
  for (int k = 0; k < 4 && std::getline(s, item, ','); ++k) v[k] = std::strtod(item.c_str(), nullptr);
  return v;
}

}  // namespace

std::optional<int> parse_args(int argc, char** argv, Options* o) {
  CLI::App app(kDescription, "make_model");
  tool::describe(app, kUsage, kExitStatus);
  auto in = [](const std::string& bounds, double lo, double hi) {
    return tool::number(bounds, [lo, hi](double x) { return x >= lo && x <= hi; });
  };
  CLI::Option* surface =
      app.add_option("--surface", o->surface,
                     "closed liver surface: .stl (ASCII or binary), .obj, .ply (ASCII or binary),\n"
                     ".vtk (legacy polydata, ASCII or binary)")
          ->option_text("FILE");
  CLI::Option* label_map =
      app.add_option("--label-map", o->label_map,
                     "instead of --surface: a label map, .nii, .nii.gz (NIfTI-1), .nrrd, .seg.nrrd;\n"
                     "its own spacing, origin, direction and unit (LPS; NIfTI's RAS converted)")
          ->option_text("FILE")
          ->excludes(surface);
  app.add_option("--label", o->label,
                 "the liver's label in --label-map: a number, or a segment name of a .seg.nrrd\n"
                 "(default 1)")
      ->option_text("L")
      ->check(CLI::Validator([](std::string& s) { return s.empty() ? "a number or a segment name" : ""; }, "L"));
  std::string resurface = "auto";
  app.add_option("--resurface", resurface,
                 "rebuild the surface from a voxel volume (ray votes, Gaussian smoothing, contour):\n"
                 "auto (default) when the surface has holes, crossings or non-manifold parts, splits\n"
                 "into many patches (stair-steps, noise), or gmsh fails or misses the quality on it;\n"
                 "always; never. A label map is always re-surfaced")
      ->option_text("auto|always|never")
      ->check(CLI::IsMember({"auto", "always", "never"}));
  app.add_option("--voxel-size", o->voxel_size,
                 "grid step for re-surfacing a surface, > 0 (input unit; default 1 mm)")
      ->option_text("V")
      ->check(tool::positive());
  app.add_option("--smoothing", o->smoothing,
                 "width (standard deviation) of the smoothing when re-surfacing, > 0 (input unit;\n"
                 "default 1 mm): stair-steps and noise finer than this go")
      ->option_text("S")
      ->check(tool::positive());
  app.add_option("--min-dihedral", o->min_dihedral,
                 "quality every tetrahedron must reach, in [1, 30] degrees (default 10)")
      ->option_text("DEG")
      ->check(in("in [1, 30]", 1, 30));
  app.add_option("--out", o->out,
                 "output folder (created if missing): NAME.msh (Gmsh 2.2), NAME.yaml (scene),\n"
                 "NAME_<vessel>.vtk (vessel trees); required")
      ->option_text("DIR")
      ->required();
  app.add_option("--name", o->name, "base name of the outputs: letters, digits, _ and - (default liver)")
      ->option_text("NAME")
      ->check(CLI::Validator([](std::string& s) { return is_name(s) ? "" : "letters, digits, _ and - only"; }, "NAME"));
  app.add_option("--unit", o->unit_name, "length unit of the input files (default mm)")
      ->option_text("mm|cm|m")
      ->check(CLI::IsMember({"mm", "cm", "m"}));
  std::string frame = "LPS";
  app.add_option("--input-frame", frame,
                 "patient frame of the input files (default LPS: DICOM, ITK, 3D Slicer >= 4.11;\n"
                 "RAS: older 3D Slicer files); RAS is turned to LPS (x and y negated)")
      ->option_text("LPS|RAS")
      ->check(CLI::IsMember({"LPS", "RAS"}));
  CLI::Option* elements =
      app.add_option("--elements", o->elements,
                     "target number of tetrahedra, in [500, 200000] (default 10000; met within 15%)")
          ->option_text("N")
          ->check(tool::integer("in [500, 200000]", [](long n) { return n >= 500 && n <= 200000; }));
  app.add_option("--size", o->size,
                 "target element edge length, > 0 (input unit), instead of --elements; at most\n"
                 "1,000,000 tetrahedra")
      ->option_text("L")
      ->check(tool::positive())
      ->excludes(elements);
  app.add_option("--feature-angle", o->feature_angle,
                 "surface creases sharper than this stay edges of the mesh, in [10, 90] degrees\n"
                 "(default 40)")
      ->option_text("DEG")
      ->check(in("in [10, 90]", 10, 90));
  app.add_option("--max-deviation", o->max_deviation,
                 "curved parts of the boundary get shorter edges so that the mesh stays within D\n"
                 "of the surface, > 0 (input unit; default 0.5 mm)")
      ->option_text("D")
      ->check(tool::positive());
  app.add_option("--max-hausdorff", o->max_hausdorff,
                 "target: the mesh's boundary and the surface it meshed lie within D of each other,\n"
                 "> 0 (input unit; default 1.5 mm)")
      ->option_text("D")
      ->check(tool::positive());
  app.add_option("--coarsen-within", o->coarsen_within,
                 "a re-surfaced boundary is coarsened while it stays within C of its surface (few\n"
                 "triangles for that distance); 0: kept as remeshed at --max-deviation; the sliver\n"
                 "repair may then move a coarsened boundary by --max-hausdorff - C. In [0,\n"
                 "--max-hausdorff) (input unit; default 0.7 --max-hausdorff)")
      ->option_text("C")
      ->check(tool::non_negative());
  app.add_option("--max-volume-change", o->max_volume_change,
                 "target: the mesh's volume within PCT percent of the surface's, in (0, 100]\n"
                 "(default 1)")
      ->option_text("PCT")
      ->check(in("in (0, 100]", 1e-9, 100));
  app.add_option("--merge-distance", o->merge_distance,
                 "vertices closer than D are merged, >= 0 (input unit; default 0: 1e-6 of the\n"
                 "surface's bounding-box diagonal)")
      ->option_text("D")
      ->check(tool::non_negative());
  app.add_flag("--largest-shell", o->largest_shell,
               "several disconnected shells: keep the largest (by volume) instead of refusing");
  app.add_option("--fixed", o->landmarks,
                 "attachment by anatomy (repeatable): bare_area, a sphere of 0.25 times the liver's\n"
                 "largest extent on its most posterior-superior point (the default when neither\n"
                 "--fixed nor --fixed-sphere is given)")
      ->option_text("LANDMARK")
      ->allow_extra_args(false)
      ->check(CLI::IsMember({"bare_area"}));
  std::vector<std::string> spheres;
  app.add_option("--fixed-sphere", spheres,
                 "attachment: nodes within R of (X, Y, Z), input unit and frame, R > 0 (repeatable)")
      ->option_text("X,Y,Z,R")
      ->allow_extra_args(false)
      ->check(sphere_text());
  app.add_option("--posture", o->posture,
                 "direction of gravity, 9.81 m/s^2 (default supine: toward the patient's back, +y;\n"
                 "prone -y; upright -z)")
      ->option_text("supine|prone|upright")
      ->check(CLI::IsMember({"supine", "prone", "upright"}));
  std::vector<std::string> vessels;
  app.add_option("--vessels", vessels,
                 "vessel centrelines (repeatable), input unit and frame: legacy VTK polydata\n"
                 "polylines with `radius` or VMTK's `MaximumInscribedSphereRadius`, or the\n"
                 "package's .yaml trees; NAME: letters, digits, _ and -")
      ->option_text("NAME=FILE")
      ->allow_extra_args(false)
      ->check(CLI::Validator(
          [](std::string& v) -> std::string {
            const size_t eq = v.find('=');
            return eq != std::string::npos && is_name(v.substr(0, eq)) && eq + 1 < v.size()
                       ? ""
                       : "expected NAME=FILE with a NAME of letters, digits, _ and -, got '" + v + "'";
          },
          "NAME=FILE"));
  app.add_option("--wall-ratio", o->wall_ratio,
                 "vessel wall thickness as a fraction of the radius where the file has no\n"
                 "`wall_thickness`, in (0, 1] (default 0.1)")
      ->option_text("R")
      ->check(tool::number("in (0, 1]", [](double x) { return x > 0 && x <= 1; }));
  app.add_option("--snap-tolerance", o->snap_tolerance,
                 "vessel nodes at most D outside the mesh are moved onto it, >= 0 (input unit;\n"
                 "default 1 mm)")
      ->option_text("D")
      ->check(tool::non_negative());
  app.add_option("--boundary-out", o->boundary_out,
                 "also write the model's boundary surface (format by extension) in the input's\n"
                 "unit and frame, to overlay on the segmentation")
      ->option_text("FILE");
  app.add_option("--time-limit", o->time_limit,
                 "wall time the whole run may take, in [1, 86400] s (default 600): past it\n"
                 "make_model stops with exit status 1 and says so (each gmsh session also has a\n"
                 "budget of its own, 30 s + 1 ms per tetrahedron, at most 300 s, past which the\n"
                 "next way to mesh is tried)")
      ->option_text("S")
      ->check(in("in [1, 86400]", 1, 86400));
  app.add_flag("--quiet", o->quiet, "no progress on standard error");
  app.callback([&] {
    if (surface->count() + label_map->count() == 0) throw CLI::ValidationError("give one of --surface and --label-map");
    if (label_map->count() > 0 && resurface == "never")
      throw CLI::ValidationError("--resurface never: a label map is always re-surfaced");
  });
  if (const std::optional<int> status = tool::parse(app, argc, argv)) return status;

  o->resurface = resurface == "always" ? Resurface::Always : resurface == "never" ? Resurface::Never : Resurface::Auto;
  o->unit = o->unit_name == "mm" ? 1e-3 : o->unit_name == "cm" ? 1e-2 : 1.0;
  o->frame = frame == "RAS" ? PatientFrame::RAS : PatientFrame::LPS;
  if (o->coarsen_within >= 0 && o->coarsen_within * o->unit >= hausdorff_bound(*o)) {
    std::cerr << "make_model: --coarsen-within " << o->coarsen_within << " must be below --max-hausdorff ("
              << hausdorff_bound(*o) / o->unit << " " << o->unit_name << "): the sliver repair needs the rest (see make_model --help)\n";
    return tool::kBadCommandLine;
  }
  for (const std::string& s : spheres) o->spheres.push_back(parse_sphere(s));
  for (const std::string& v : vessels) {
    const size_t eq = v.find('=');
    const Vessel vessel{v.substr(0, eq), v.substr(eq + 1)};
    for (const Vessel& other : o->vessels)
      if (other.name == vessel.name) {
        std::cerr << "make_model: --vessels: the name '" << vessel.name << "' is given twice (see make_model --help)\n";
        return tool::kBadCommandLine;
      }
    o->vessels.push_back(vessel);
  }
  return std::nullopt;
}

}  // namespace liver_sim
