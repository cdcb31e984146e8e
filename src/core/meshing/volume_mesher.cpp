#include "liver_sim/meshing/volume_mesher.h"

#include <gmsh.h>
#include <pcl/kdtree/kdtree_flann.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <optional>
#include <sstream>
#include <type_traits>
#include <vector>

#include "liver_sim/meshing/surface_coarsen.h"
#include "liver_sim/meshing/surface_remesh.h"
#include "liver_sim/meshing/surface_repair.h"
#include "liver_sim/runtime/child_process.h"

namespace liver_sim {
namespace {

// gmsh keeps one global model: initialised here, finalised on every way out.
struct GmshSession {
  GmshSession() {
    gmsh::initialize(0, nullptr, false);  // no user configuration files: the same options everywhere
    gmsh::option::setNumber("General.Terminal", 0);
    // Errors are read from the log (gmsh_error): thrown inside gmsh's OpenMP regions they would
    // end the process.
    gmsh::option::setNumber("General.AbortOnError", 0);
    gmsh::logger::start();
    gmsh::option::setNumber("General.NumThreads", 1);
    gmsh::option::setNumber("Mesh.RandomSeed", 1);
    gmsh::option::setNumber("Mesh.Algorithm", 6);    // surfaces: Frontal-Delaunay
    gmsh::option::setNumber("Mesh.Algorithm3D", 1);  // volume: Delaunay
    gmsh::option::setNumber("Mesh.Optimize", 1);     // gmsh's tetrahedron optimiser (slivers)
    gmsh::option::setNumber("Mesh.MeshSizeFromPoints", 0);
    gmsh::option::setNumber("Mesh.MeshSizeFromCurvature", 0);
    gmsh::option::setNumber("Mesh.MeshSizeExtendFromBoundary", 0);
  }
  ~GmshSession() {
    gmsh::logger::stop();
    gmsh::finalize();
  }
};

// The first error gmsh logged since the last call ("" when none); the log starts afresh.
std::string gmsh_error() {
  std::vector<std::string> log;
  gmsh::logger::get(log);
  gmsh::logger::stop();
  gmsh::logger::start();
  for (const std::string& line : log)
    if (line.rfind("Error", 0) == 0) return line;
  return "";
}

// Tetrahedra per unit volume at edge length h, measured on liver shapes with these options
// (the phantom and SOFA's liver2: 4.88 and 4.93 h^-3).
constexpr double kTetsPerCubicSize = 4.9;

// Mesh size from the surface's curvature: an edge of length L on a surface of curvature k bulges
// L^2 k / 8 from it, so L = sqrt(8 deviation / k) keeps the mesh within `deviation`, clamped to
// [h / 4, h]. The curvature at a vertex is the largest turn of the normal per unit length toward
// the vertices between h / 8 and h / 2 away: over that span a segmentation's voxel steps average
// out. Looked up at the nearest vertex.
class CurvatureSize {
 public:
  CurvatureSize(const SurfaceMesh& s, double h, double deviation, double feature_angle)
      : cloud_(new pcl::PointCloud<pcl::PointXYZ>) {
    const double crease = std::cos(feature_angle * M_PI / 180.0);
    const Eigen::Index n = s.V.rows();
    Eigen::MatrixX3d normal = Eigen::MatrixX3d::Zero(n, 3);
    for (Eigen::Index t = 0; t < s.F.rows(); ++t) {
      const Eigen::RowVector3d a = s.V.row(s.F(t, 0)), b = s.V.row(s.F(t, 1)), c = s.V.row(s.F(t, 2));
      const Eigen::RowVector3d area_normal = (b - a).cross(c - a);  // twice the area, outward
      for (int k = 0; k < 3; ++k) normal.row(s.F(t, k)) += area_normal;
    }
    normal.rowwise().normalize();
    for (Eigen::Index i = 0; i < n; ++i) cloud_->push_back(pcl::PointXYZ(s.V(i, 0), s.V(i, 1), s.V(i, 2)));
    tree_.setInputCloud(cloud_);
    size_.resize(n);
    std::vector<int> found;
    std::vector<float> squared;
    for (Eigen::Index i = 0; i < n; ++i) {
      tree_.radiusSearch(cloud_->points[i], 0.5 * h, found, squared);
      double curvature = 0;
      for (const int j : found) {
        const double d = (s.V.row(j) - s.V.row(i)).norm();
        // Normals turned by more than the feature angle lie across a crease, which gmsh keeps as
        // an edge of the mesh: no chordal error there.
        if (d >= 0.125 * h && normal.row(j).dot(normal.row(i)) > crease)
          curvature = std::max(curvature, (normal.row(j) - normal.row(i)).norm() / d);
      }
      size_[i] = curvature > 0 ? std::clamp(std::sqrt(8 * deviation / curvature), 0.25 * h, h) : h;
    }
  }
  double operator()(double x, double y, double z) const {
    std::vector<int> found(1);
    std::vector<float> squared(1);
    tree_.nearestKSearch(pcl::PointXYZ(x, y, z), 1, found, squared);
    return size_[found[0]];
  }

 private:
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud_;
  pcl::KdTreeFLANN<pcl::PointXYZ> tree_;
  std::vector<double> size_;
};

TetMesh extract(const std::string& origin) {
  std::vector<std::size_t> tags;
  std::vector<double> coords, parametric;
  gmsh::model::mesh::getNodes(tags, coords, parametric, -1, -1, false, false);
  std::vector<std::size_t> elements, nodes;
  gmsh::model::mesh::getElementsByType(4, elements, nodes);
  if (elements.empty() || tags.empty()) throw MeshError(origin + ": gmsh made no tetrahedra");
  std::vector<int> row_of_tag(*std::max_element(tags.begin(), tags.end()) + 1, -1);
  for (size_t i = 0; i < tags.size(); ++i) row_of_tag[tags[i]] = static_cast<int>(i);
  // Nodes numbered in the order the tetrahedra first use them; nodes of no tetrahedron (the
  // input surface's, kept by gmsh as the patches' geometry) drop out.
  std::vector<int> new_index(tags.size(), -1), order;
  TetMesh m;
  m.T.resize(static_cast<Eigen::Index>(elements.size()), 4);
  for (size_t e = 0; e < elements.size(); ++e)
    for (int k = 0; k < 4; ++k) {
      const int row = row_of_tag.at(nodes[4 * e + k]);
      if (new_index[row] < 0) {
        new_index[row] = static_cast<int>(order.size());
        order.push_back(row);
      }
      m.T(e, k) = new_index[row];
    }
  m.V.resize(static_cast<Eigen::Index>(order.size()), 3);
  for (size_t i = 0; i < order.size(); ++i)
    for (int c = 0; c < 3; ++c) m.V(i, c) = coords[3 * order[i] + c];
  validate_mesh(m, origin + ": gmsh's mesh");  // positively oriented, as gmsh makes them
  return m;
}


// Raised when gmsh fails to mesh the patches with the sizes asked for.
struct SizingFailure {
  std::string message;
};

// The surface's nodes and triangles as one discrete surface of the current gmsh model; its tag.
int add_discrete_surface(const SurfaceMesh& surface) {
  const int patch = gmsh::model::addDiscreteEntity(2);
  std::vector<std::size_t> node_tags(surface.V.rows());
  std::iota(node_tags.begin(), node_tags.end(), std::size_t{1});
  std::vector<double> coords(3 * surface.V.rows());
  for (Eigen::Index i = 0; i < surface.V.rows(); ++i)
    for (int c = 0; c < 3; ++c) coords[3 * i + c] = surface.V(i, c);
  gmsh::model::mesh::addNodes(2, patch, node_tags, coords);
  std::vector<std::size_t> triangle_tags(surface.F.rows()), corners(3 * surface.F.rows());
  std::iota(triangle_tags.begin(), triangle_tags.end(), std::size_t{1});
  for (Eigen::Index t = 0; t < surface.F.rows(); ++t)
    for (int k = 0; k < 3; ++k) corners[3 * t + k] = static_cast<std::size_t>(surface.F(t, k)) + 1;
  gmsh::model::mesh::addElementsByType(patch, 2, triangle_tags, corners);
  return patch;
}

// What a gmsh session sends back from its child process: how it ended, its message, the report
// and the mesh, as bytes.
enum class SessionEnd : char { kMesh, kSizingFailure, kMeshError, kRoughSurface };

template <class T>
void put(std::string& bytes, const T& x) {
  static_assert(std::is_trivially_copyable_v<T>);
  bytes.append(reinterpret_cast<const char*>(&x), sizeof x);
}

template <class T>
T take(const std::string& bytes, size_t& at) {
  T x;
  std::memcpy(&x, bytes.data() + at, sizeof x);
  at += sizeof x;
  return x;
}

std::string pack(SessionEnd end, const std::string& message, const VolumeMeshReport& r, const TetMesh& m) {
  std::string bytes;
  put(bytes, end);
  put(bytes, message.size());
  bytes += message;
  put(bytes, r);
  put(bytes, m.V.rows());
  put(bytes, m.T.rows());
  bytes.append(reinterpret_cast<const char*>(m.V.data()), sizeof(double) * m.V.size());
  bytes.append(reinterpret_cast<const char*>(m.T.data()), sizeof(int) * m.T.size());
  return bytes;
}

// gmsh has been seen to loop without end on rare surfaces, and, with the heap in another state
// (another environment), on a surface it meshes here in a second: each session runs in a child process
// (child_process.h) and is stopped past `budget` seconds. What the session threw is thrown here;
// a session stopped or crashed throws SizingFailure when it sized by curvature (the uniform size
// is tried next), MeshError otherwise.
TetMesh in_child_process(const std::function<TetMesh(VolumeMeshReport&, const ChildProgress&)>& session, double budget,
                         bool curvature_sizing, const std::string& origin, VolumeMeshReport& r,
                         const ChildProgress& progress) {
  const ChildOutcome outcome = run_in_child(
      [&](const ChildProgress& child_progress) {
        VolumeMeshReport report = r;
        try {
          const TetMesh m = session(report, child_progress);
          return pack(SessionEnd::kMesh, "", report, m);
        } catch (const SizingFailure& failure) {
          return pack(SessionEnd::kSizingFailure, failure.message, report, TetMesh());
        } catch (const RoughSurfaceError& e) {
          return pack(SessionEnd::kRoughSurface, e.what(), report, TetMesh());
        } catch (const MeshError& e) {
          return pack(SessionEnd::kMeshError, e.what(), report, TetMesh());
        } catch (const std::string& message) {  // gmsh's exceptions outside its parallel regions
          return pack(SessionEnd::kMeshError, origin + ": gmsh: " + message, report, TetMesh());
        }
      },
      budget, progress);
  if (outcome.status != ChildOutcome::Status::kFinished) {
    ++r.passes;
    std::ostringstream why;
    if (outcome.status == ChildOutcome::Status::kTimedOut)
      why << "gmsh did not finish in " << budget << " s and was stopped";
    else
      why << "gmsh's process ended (" << outcome.reason << ")";
    if (curvature_sizing) throw SizingFailure{why.str()};
    throw MeshError(origin + ": " + why.str());
  }
  const std::string& bytes = outcome.result;
  size_t at = 0;
  const auto end = take<SessionEnd>(bytes, at);
  const auto length = take<size_t>(bytes, at);
  const std::string message = bytes.substr(at, length);
  at += length;
  r = take<VolumeMeshReport>(bytes, at);
  TetMesh m;
  m.V.resize(take<Eigen::Index>(bytes, at), 3);
  m.T.resize(take<Eigen::Index>(bytes, at), 4);
  std::copy_n(bytes.data() + at, sizeof(double) * m.V.size(), reinterpret_cast<char*>(m.V.data()));
  std::copy_n(bytes.data() + at + sizeof(double) * m.V.size(), sizeof(int) * m.T.size(), reinterpret_cast<char*>(m.T.data()));
  switch (end) {
    case SessionEnd::kSizingFailure:
      throw SizingFailure{message};
    case SessionEnd::kRoughSurface:
      throw RoughSurfaceError(message);
    case SessionEnd::kMeshError:
      throw MeshError(message);
    case SessionEnd::kMesh:
      break;
  }
  return m;
}

// A session's time budget for about `tetrahedra`: far above what meshing takes (gmsh made
// 200,000 tetrahedra of the phantom in 5 s, its passes included), at most 300 s.
double session_budget(double tetrahedra) {
  return std::isfinite(tetrahedra) && tetrahedra > 0 ? std::min(300.0, 30 + 1e-3 * tetrahedra) : 300.0;
}

// One gmsh session from the input triangles to the tetrahedra.
TetMesh mesh_in_session(const SurfaceMesh& surface, const std::string& origin, const VolumeMeshOptions& options,
                        double h, bool curvature_sizing, VolumeMeshReport& r,
                        const std::function<void(const std::string&)>& progress) {
  GmshSession session;
  gmsh::model::add("liver");
  add_discrete_surface(surface);

  progress("classifying the surface (" + std::to_string(surface.F.rows()) + " triangles) into patches");
  gmsh::model::mesh::classifySurfaces(options.feature_angle * M_PI / 180.0, true, true, M_PI);
  gmsh::model::mesh::createGeometry();
  if (const std::string error = gmsh_error(); !error.empty())
    throw MeshError(origin + ": gmsh could not make patches of the surface: " + error);
  std::vector<std::pair<int, int>> surfaces;
  gmsh::model::getEntities(surfaces, 2);
  if (options.max_patches > 0 && static_cast<int>(surfaces.size()) > options.max_patches)
    throw RoughSurfaceError(origin + ": stair-steps or noise: the surface splits into " + std::to_string(surfaces.size()) +
                            " patches at the feature angle (a smooth liver: a few)");
  std::vector<int> surface_tags;
  for (const auto& [dim, tag] : surfaces) surface_tags.push_back(tag);
  const int loop = gmsh::model::geo::addSurfaceLoop(surface_tags);
  gmsh::model::geo::addVolume({loop});
  gmsh::model::geo::synchronize();

  for (int corrections = 0;; ++corrections) {
    ++r.passes;
    r.element_size = h;
    gmsh::option::setNumber("Mesh.MeshSizeMax", h);
    std::optional<CurvatureSize> sizing;
    if (curvature_sizing) {
      progress("sizing elements by the surface's curvature (deviation " + std::to_string(options.max_deviation * 1e3) +
               " mm)");
      sizing.emplace(surface, h, options.max_deviation, options.feature_angle);
      gmsh::model::mesh::setSizeCallback([&](int, int, double x, double y, double z) { return (*sizing)(x, y, z); });
    }
    progress("meshing surface and volume at " + std::to_string(h * 1e3) + " mm (pass " + std::to_string(r.passes) +
             ", " + std::to_string(surfaces.size()) + " patches)");
    gmsh::model::mesh::generate(3);
    if (curvature_sizing) gmsh::model::mesh::removeSizeCallback();
    if (const std::string error = gmsh_error(); !error.empty()) {
      if (curvature_sizing) throw SizingFailure{error};
      throw MeshError(origin + ": gmsh: " + error);
    }
    std::vector<std::size_t> tets, tet_nodes;
    gmsh::model::mesh::getElementsByType(4, tets, tet_nodes);
    const double n = static_cast<double>(tets.size());
    // Up to four corrections when the count was asked for and missed by more than 15%.
    if (options.element_size > 0 || corrections == 4 || n == 0 || std::abs(n / options.target_elements - 1.0) <= 0.15)
      break;
    h *= std::cbrt(n / options.target_elements);
    gmsh::model::mesh::clear();
  }
  return extract(origin);
}

// The surface remeshed at sizes from its curvature and thickness (at most h) and filled. When the
// count misses, h is corrected along the count's power law in h as the last two passes measured
// it (the boundary's curvature-bound edges make it flatter than h^-3; h^-3 for the first step).
TetMesh remesh_and_fill(const SurfaceMesh& surface, const std::string& origin, const VolumeMeshOptions& options,
                        double h, VolumeMeshReport& r, const std::function<void(const std::string&)>& progress) {
  double last_h = 0, last_n = 0;
  // Past twice the size the count asks of a uniform mesh, the inside's tetrahedra grow too large
  // for the boundary's: poorly shaped, stiff in the model. The count is missed instead.
  const double largest = 2 * h;
  for (int corrections = 0;; ++corrections) {
    ++r.passes;
    r.element_size = h;
    r.curvature_sizing = true;
    // The shortest edge: one whose bulge on a bend of radius `deviation` is half of it; a
    // re-surfaced surface, blurred, bends no tighter.
    const double shortest = std::min(4 * options.max_deviation, h);
    progress("remeshing the surface (" + std::to_string(surface.F.rows()) + " triangles) at " +
             std::to_string(shortest * 1e3) + "-" + std::to_string(h * 1e3) + " mm (pass " + std::to_string(r.passes) + ")");
    RemeshOptions remesh;
    remesh.deviation = options.max_deviation;
    remesh.min_size = shortest;
    std::vector<double> sizes = curvature_sizes(surface, options.max_deviation, shortest, h, options.gradation);
    SurfaceMesh boundary;
    // Where the remeshed sheets still cross (a gap the thickness bound underestimated), shorter
    // edges everywhere, twice at most; then the crossing is reported where it is.
    for (int retry = 0;; ++retry) {
      boundary = remesh_surface(surface, sizes, remesh, origin);
      if (options.coarsen_within > 0) {
        CoarsenOptions coarsen;
        coarsen.tolerance = options.coarsen_within;
        coarsen.max_edge = 4.0 / 3.0 * *std::max_element(sizes.begin(), sizes.end());  // the remeshing's longest
        boundary = coarsen_surface(boundary, surface, coarsen, origin);
      }
      try {
        repair_surface(boundary, origin + " (remeshed)");  // closed, manifold, not crossing itself
        break;
      } catch (const SurfaceDefectError& e) {
        if (retry == 2) throw;
        progress(std::string(e.what()) + ": remeshing with edges 0.7 times as long");
        for (double& size : sizes) size *= 0.7;
      }
    }
    progress("filling the volume (" + std::to_string(boundary.F.rows()) + " boundary triangles)");
    TetMesh m = fill_volume(boundary, h, origin);
    const double n = static_cast<double>(m.T.rows());
    if (options.element_size > 0 || corrections == 4 || std::abs(n / options.target_elements - 1.0) <= 0.15 ||
        (h >= largest && n > options.target_elements))
      return m;
    double exponent = last_n > 0 && n != last_n ? std::log(n / last_n) / std::log(h / last_h) : -3;
    exponent = std::clamp(exponent, -3.0, -0.75);  // steps of at most (n / target)^(4/3) in h
    last_h = h, last_n = n;
    h = std::min(largest, h * std::pow(options.target_elements / n, 1 / exponent));
  }
}

}  // namespace

TetMesh mesh_volume(const SurfaceMesh& surface, const std::string& origin, const VolumeMeshOptions& options,
                    VolumeMeshReport* report) {
  auto progress = [&](const std::string& s) {
    if (options.progress) options.progress(s);
  };
  double h = options.element_size;
  if (!(h > 0)) {
    if (options.target_elements < 1) throw MeshError(origin + ": the target element count must be >= 1");
    h = std::cbrt(kTetsPerCubicSize * enclosed_volume(surface) / options.target_elements);
  }
  if (!(h > 0) || !std::isfinite(h)) throw MeshError(origin + ": no valid element size");
  VolumeMeshReport r;
  if (options.remesh_boundary) {
    TetMesh m = remesh_and_fill(surface, origin, options, h, r, progress);
    if (report) *report = r;
    return m;
  }
  const double budget = session_budget(kTetsPerCubicSize * enclosed_volume(surface) / std::pow(h, 3));
  auto session = [&](bool curvature_sizing) {
    return in_child_process(
        [&](VolumeMeshReport& session_report, const ChildProgress& session_progress) {
          return mesh_in_session(surface, origin, options, h, curvature_sizing, session_report, session_progress);
        },
        budget, curvature_sizing, origin, r, progress);
  };
  TetMesh m;
  try {
    m = session(true);
  } catch (const SizingFailure& failure) {
    // Fine elements next to coarse ones can defeat gmsh's recovery of patch edges; a uniform
    // size is the safe fall-back (the Hausdorff distance says what it costs).
    progress("gmsh failed with curvature sizing (" + failure.message + "): meshing at a uniform size");
    r.curvature_sizing = false;
    m = session(false);
  }
  if (report) *report = r;
  return m;
}

TetMesh fill_volume(const SurfaceMesh& boundary, double max_size, const std::string& origin) {
  if (!(max_size > 0) || !std::isfinite(max_size)) throw MeshError(origin + ": no valid element size");
  // About as many tetrahedra as the size makes inside and a few per boundary triangle.
  const double tetrahedra = kTetsPerCubicSize * enclosed_volume(boundary) / std::pow(max_size, 3) + 4.0 * boundary.F.rows();
  VolumeMeshReport unused;
  return in_child_process(
      [&](VolumeMeshReport&, const ChildProgress&) {
        GmshSession session;
        gmsh::model::add("liver");
        const int patch = add_discrete_surface(boundary);
        // A discrete surface without a parametrisation keeps its triangles: only the volume is meshed.
        gmsh::model::geo::addVolume({gmsh::model::geo::addSurfaceLoop({patch})});
        gmsh::model::geo::synchronize();
        gmsh::option::setNumber("Mesh.MeshSizeMax", max_size);
        gmsh::model::mesh::generate(3);
        if (const std::string error = gmsh_error(); !error.empty()) throw MeshError(origin + ": gmsh: " + error);
        return extract(origin);
      },
      session_budget(tetrahedra), false, origin, unused, nullptr);
}

}  // namespace liver_sim
