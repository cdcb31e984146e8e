#include "make_model_mesh.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "liver_sim/io/label_map_io.h"
#include "liver_sim/io/surface_io.h"

namespace liver_sim {
namespace {

// A smooth liver surface splits into a few patches at the feature angle (the phantom and SOFA's
// livers: 2-5); a segmentation's stair-steps into dozens or hundreds (3D-IRCADb's: 46).
constexpr int kMaxPatches = 20;

int resolve_label(const std::string& text, const LabelImage& image, const std::string& origin) {
  char* end = nullptr;
  const long v = std::strtol(text.c_str(), &end, 10);
  if (end == text.c_str() + text.size() && std::abs(v) < (1L << 31)) return static_cast<int>(v);
  std::string names;
  for (const auto& [name, value] : image.segments) {
    if (name == text) return value;
    names += (names.empty() ? "" : ", ") + name + " (" + std::to_string(value) + ")";
  }
  throw MeshError(origin + ": no segment named '" + text + "'" + (names.empty() ? " (the file names none)" : "; segments: " + names));
}

std::string join(const std::string& a, const std::string& b) { return a.empty() ? b : b.empty() ? a : a + "; " + b; }

std::string fixed(double x, int digits) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(digits);
  s << x;
  return s.str();
}

// The mesh's own targets (smallest dihedral angle, element count), each missed one with its
// value, the bound and why; empty when both are met.
std::string missed_mesh_targets(const Options& o, const TetQuality& q, const TetMesh& mesh, const VolumeMeshReport& report,
                                bool sized, bool coarsened) {
  std::string missed;
  if (q.min_dihedral_deg < o.min_dihedral)
    missed = "smallest dihedral angle " + fixed(q.min_dihedral_deg, 2) + " deg, " +
             fixed(o.min_dihedral - q.min_dihedral_deg, 2) + " deg under --min-dihedral " + fixed(o.min_dihedral, 1) +
             " (slivers neither gmsh's optimiser nor the sliver repair could remove)";
  const double tetrahedra = static_cast<double>(mesh.T.rows());
  const double off = tetrahedra / o.elements - 1.0;
  if (!sized && std::abs(off) > kCountTolerance) {
    const Eigen::Index boundary = boundary_triangles(mesh.T).rows();
    std::ostringstream m;
    m << mesh.T.rows() << " tetrahedra for --elements " << o.elements << ": " << fixed(100 * std::abs(off), 0) << "% "
      << (off > 0 ? "over" : "under") << ", the bound is " << fixed(100 * kCountTolerance, 0) << "%";
    // A re-surfaced boundary is coarsened as far as --coarsen-within allows; gmsh's patches, and
    // a boundary left as remeshed, are refined to --max-deviation.
    const std::string bound = coarsened ? "--coarsen-within" : "--max-deviation";
    if (off > 0)
      m << " (the boundary needs " << boundary << " triangles to stay within " << bound << " of the surface, and the "
        << "volume inside them, its edges up to " << fixed(report.element_size / o.unit, 1) << " " << o.unit_name
        << ", holds " << fixed(tetrahedra / boundary, 2) << " tetrahedra per boundary triangle: ask for about "
        << mesh.T.rows() << " --elements or a larger " << bound
        << (bound == "--coarsen-within" ? " (below --max-hausdorff: the sliver repair gets the rest)" : "") << ")";
    missed = join(missed, m.str());
  }
  return missed;
}

}  // namespace

std::string missed_shape_targets(const Options& o, const SurfaceDeviation& distance, double surface_volume,
                                 double mesh_volume) {
  std::string missed;
  const double bound = hausdorff_bound(o);
  if (distance.hausdorff() > bound) {
    const OneSidedDeviation& far = distance.a_to_b.max >= distance.b_to_a.max ? distance.a_to_b : distance.b_to_a;
    const Eigen::Vector3d at = far.farthest / o.unit;
    missed = "Hausdorff distance " + fixed(distance.hausdorff() / o.unit, 2) + " " + o.unit_name +
             " between the mesh's boundary and the surface it meshed, " + fixed((distance.hausdorff() - bound) / o.unit, 2) +
             " " + o.unit_name + " over --max-hausdorff " + fixed(bound / o.unit, 2) + " (farthest at (" + fixed(at[0], 1) +
             ", " + fixed(at[1], 1) + ", " + fixed(at[2], 1) + ") " + o.unit_name + ", LPS)";
  }
  const double off = mesh_volume / surface_volume - 1.0;
  if (std::abs(100 * off) > o.max_volume_change)
    missed = join(missed, "the mesh's volume " + fixed(100 * off, 2) + "% from the surface's, " +
                              fixed(std::abs(100 * off) - o.max_volume_change, 2) + " points over --max-volume-change " +
                              fixed(o.max_volume_change, 2) + "% (the boundary's chords cut the curved surface)");
  return missed;
}

ModelMesh make_model_mesh(const Options& o, const std::function<void(const std::string&)>& say) {
  ModelMesh r;
  Stopwatch clock;
  ResurfaceOptions rs;
  rs.voxel_size = o.voxel_size > 0 ? o.voxel_size * o.unit : 1e-3;
  rs.smoothing = o.smoothing > 0 ? o.smoothing * o.unit : 1e-3;
  rs.keep_largest = o.largest_shell;
  auto resurface_input = [&](const std::string& reason) {
    say("re-surfacing: " + reason);
    r.resurfaced = true;
    r.resurface_reason = reason;
    r.surface = resurface(r.input, rs, r.input_name, &r.resurfacing);
    for (const std::string& note : r.resurfacing.notes) say(note);
    r.times.emplace_back("resurface", clock.lap());
  };

  if (!o.label_map.empty()) {
    r.input_name = o.label_map;
    say("reading " + o.label_map);
    const LabelImage image = read_label_map(o.label_map);
    r.times.emplace_back("read", clock.lap());
    r.label = resolve_label(o.label, image, o.label_map);
    say("positions from the " + image.orientation_source + "; label " + std::to_string(r.label));
    r.resurfaced = true;
    r.resurface_reason = "a label map";
    r.surface = resurface(image, r.label, rs, o.label_map, &r.resurfacing);
    for (const std::string& note : r.resurfacing.notes) say(note);
    r.times.emplace_back("resurface", clock.lap());
  } else {
    r.input_name = o.surface;
    say("reading " + o.surface);
    r.input = read_surface(o.surface, o.unit);
    r.input.V = to_lps(r.input.V, o.frame);
    r.input_triangles = r.input.F.rows();
    r.times.emplace_back("read", clock.lap());
    say("checking and repairing " + std::to_string(r.input_triangles) + " triangles");
    SurfaceRepairOptions repair_options;
    repair_options.merge_distance = o.merge_distance * o.unit;
    repair_options.keep_largest_shell = o.largest_shell;
    std::string defect;
    try {
      r.surface = repair_surface(r.input, o.surface, repair_options, &r.repairs);
    } catch (const SurfaceDefectError& e) {
      if (o.resurface == Resurface::Never) throw;
      defect = e.what();
      r.repairs = SurfaceRepairs();
      r.surface = r.input;
    }
    for (const std::string& note : r.repairs.notes) say(note);
    const Eigen::Vector3d extent = r.surface.V.colwise().maxCoeff() - r.surface.V.colwise().minCoeff();
    // A liver measures 10-30 cm: far outside 1 cm - 1 m the unit is wrong.
    if (extent.maxCoeff() > 1.0 || extent.maxCoeff() < 0.01) {
      std::ostringstream m;
      m << o.surface << ": the surface spans " << extent.maxCoeff() << " m with --unit " << o.unit_name
        << " (a liver spans 0.1-0.3 m; outside 0.01-1 m the unit is wrong)";
      throw MeshError(m.str());
    }
    r.times.emplace_back("repair", clock.lap());
    if (o.resurface == Resurface::Always) resurface_input("--resurface always");
    else if (!defect.empty()) {
      try {
        resurface_input(defect);
      } catch (const MeshError& e) {  // the defect first: it is what the user must mend
        throw MeshError(defect + " (re-surfacing could not mend it: " + e.what() + ")");
      }
    }
  }

  VolumeMeshOptions mesh_options;
  mesh_options.element_size = o.size * o.unit;
  mesh_options.target_elements = o.elements;
  mesh_options.feature_angle = o.feature_angle;
  mesh_options.max_deviation = o.max_deviation > 0 ? o.max_deviation * o.unit : 0.5e-3;
  mesh_options.coarsen_within = coarsening_bound(o);
  mesh_options.progress = say;
  const bool may_resurface = o.resurface == Resurface::Auto && o.label_map.empty();
  for (;;) {
    const double volume = enclosed_volume(r.surface);
    if (o.size > 0 && 4.9 * volume / std::pow(mesh_options.element_size, 3) > 1e6)
      throw CommandLineError("--size: " + std::to_string(o.size) + " " + o.unit_name +
                             " would make over 1,000,000 tetrahedra");
    mesh_options.max_patches = may_resurface && !r.resurfaced ? kMaxPatches : 0;
    mesh_options.remesh_boundary = r.resurfaced;  // a level set: smooth, no crease
    try {
      r.mesh_report = VolumeMeshReport();
      r.mesh = mesh_volume(r.surface, r.input_name, mesh_options, &r.mesh_report);
    } catch (const MeshError& e) {
      if (!may_resurface || r.resurfaced) throw;
      r.times.emplace_back("mesh", clock.lap());
      resurface_input(e.what());
      continue;
    }
    r.times.emplace_back("mesh", clock.lap());
    r.quality = tet_quality(r.mesh);
    // The boundary was coarsened: a re-surfaced surface is remeshed, then coarsened.
    const bool coarsened = r.resurfaced && coarsening_bound(o) > 0;
    if (r.quality.min_dihedral_deg < o.min_dihedral) {
      // A coarsened boundary has used that much of the Hausdorff bound: the repair gets the rest.
      r.slivers = repair_slivers(r.mesh, o.min_dihedral,
                                 coarsened ? hausdorff_bound(o) - coarsening_bound(o) : std::numeric_limits<double>::infinity());
      say("slivers: smallest dihedral angle " + std::to_string(r.slivers.before_deg) + " deg; " +
          std::to_string(r.slivers.peeled) + " peeled off the boundary, " + std::to_string(r.slivers.moved_nodes) +
          " nodes moved: " + std::to_string(r.slivers.after_deg) + " deg");
      r.quality = tet_quality(r.mesh);
      r.times.emplace_back("slivers", clock.lap());
    }
    r.missed = missed_mesh_targets(o, r.quality, r.mesh, r.mesh_report, o.size > 0, coarsened);
    if (r.missed.empty() || !may_resurface || r.resurfaced) break;
    resurface_input(r.input_name + ": " + r.missed);
  }
  return r;
}

}  // namespace liver_sim
