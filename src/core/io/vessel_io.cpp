#include "liver_sim/io/vessel_io.h"

#include <yaml-cpp/yaml.h>

#include <fstream>
#include <limits>
#include <numeric>
#include <sstream>
#include <vector>

#include "liver_sim/io/file_names.h"
#include "vtk_polydata.h"

namespace liver_sim {

VesselTree read_vessel_vtk(std::istream& stream, const std::string& origin, double scale, double wall_ratio) {
  std::ostringstream bytes;
  bytes << stream.rdbuf();
  VtkPolyData data;
  try {
    data = read_vtk_polydata(bytes.str(), origin);
  } catch (const FormatError& e) {
    throw VesselError(e.what());
  }
  if (!data.has_points) throw VesselError(origin + ": no POINTS");
  VesselTree t;
  t.points = scale * data.points;
  std::vector<Eigen::Vector2i> segments;
  const VtkCells& lines = data.lines;
  for (long long l = 0; l < lines.size(); ++l) {
    if (lines.offsets[l + 1] - lines.offsets[l] < 2)
      throw VesselError(origin + ": polyline " + std::to_string(l) + " has fewer than 2 points");
    for (long long j = lines.offsets[l] + 1; j < lines.offsets[l + 1]; ++j)
      segments.emplace_back(static_cast<int>(lines.connectivity[j - 1]), static_cast<int>(lines.connectivity[j]));
  }
  // A point array by the first of `names` the file has; empty when it has none.
  auto point_array = [&](std::initializer_list<const char*> names) {
    for (const char* name : names) {
      const auto it = data.point_arrays.find(name);
      if (it == data.point_arrays.end()) continue;
      if (it->second.cols() != 1)
        throw VesselError(origin + ": point array '" + name + "' must have 1 component, not " +
                          std::to_string(it->second.cols()));
      return Eigen::VectorXd(scale * it->second.col(0));
    }
    return Eigen::VectorXd();
  };
  const long long n = t.points.rows();
  t.radius = point_array({"radius", "MaximumInscribedSphereRadius"});
  if (t.radius.size() != n) throw VesselError(origin + ": no point array 'radius' (nor VMTK's 'MaximumInscribedSphereRadius')");
  t.wall_thickness = point_array({"wall_thickness"});
  if (t.wall_thickness.size() != n) {
    if (!(wall_ratio > 0))
      throw VesselError(origin + ": no point array 'wall_thickness' (for centrelines without one, give a wall-to-radius ratio)");
    t.wall_thickness = wall_ratio * t.radius;
  }
  t.segments.resize(static_cast<int>(segments.size()), 2);
  for (size_t s = 0; s < segments.size(); ++s) t.segments.row(s) = segments[s].transpose();
  validate_vessel_tree(t, origin);
  return t;
}

VesselTree read_vessel_yaml(const std::string& text, const std::string& origin, double scale) {
  auto fail = [&](const std::string& message) -> void { throw VesselError(origin + ": " + message); };
  // yaml-cpp recurses per nesting level; a tree file is two levels deep.
  int depth = 0;
  for (char c : text) {
    depth = std::max(0, depth + (c == '[' || c == '{') - (c == ']' || c == '}'));
    if (depth > 8) fail("nested deeper than 8 levels");
  }
  VesselTree t;
  try {
    const YAML::Node root = YAML::Load(text);
    if (!root.IsMap()) fail("expected a map with nodes and segments");
    for (const auto& kv : root) {
      const std::string key = kv.first.as<std::string>();
      if (key != "nodes" && key != "segments") fail("unknown key '" + key + "'");
    }
    const YAML::Node nodes = root["nodes"], segments = root["segments"];
    if (!nodes || !nodes.IsSequence()) fail("nodes: expected a list of [x, y, z, radius, wall_thickness]");
    if (!segments || !segments.IsSequence()) fail("segments: expected a list of [node, node]");
    const int n = static_cast<int>(nodes.size());
    t.points.resize(n, 3);
    t.radius.resize(n);
    t.wall_thickness.resize(n);
    for (int i = 0; i < n; ++i) {
      const YAML::Node v = nodes[i];
      if (!v.IsSequence() || v.size() != 5)
        fail("node " + std::to_string(i) + ": expected [x, y, z, radius, wall_thickness]");
      double a[5];
      for (int c = 0; c < 5; ++c) {
        if (!v[c].IsScalar()) fail("node " + std::to_string(i) + ": expected numbers");
        a[c] = scale * v[c].as<double>();
      }
      t.points.row(i) << a[0], a[1], a[2];
      t.radius[i] = a[3];
      t.wall_thickness[i] = a[4];
    }
    t.segments.resize(static_cast<int>(segments.size()), 2);
    for (size_t s = 0; s < segments.size(); ++s) {
      const YAML::Node v = segments[s];
      if (!v.IsSequence() || v.size() != 2 || !v[0].IsScalar() || !v[1].IsScalar())
        fail("segment " + std::to_string(s) + ": expected [node, node]");
      for (int c = 0; c < 2; ++c) {
        const long long k = v[c].as<long long>();
        if (k < 0 || k >= n) fail("segment " + std::to_string(s) + ": node " + v[c].Scalar() + " out of range");
        t.segments(s, c) = static_cast<int>(k);
      }
    }
  } catch (const YAML::Exception& e) {
    fail(std::string("YAML: ") + e.what());
  }
  validate_vessel_tree(t, origin);
  return t;
}

VesselTree read_vessel_tree(const std::string& path, double scale, double wall_ratio) {
  std::ifstream in(path);
  if (!in) throw VesselError(path + ": cannot open");
  const std::string ext = file_extension(path);
  if (ext == "vtk") return read_vessel_vtk(in, path, scale, wall_ratio);
  if (ext != "yaml" && ext != "yml") throw VesselError(path + ": unknown vessel format (expected .vtk, .yaml or .yml)");
  std::stringstream text;
  text << in.rdbuf();
  return read_vessel_yaml(text.str(), path, scale);
}

void write_vessel_vtk(const std::string& path, const VesselTree& t, const std::string& title) {
  std::ofstream out(path);
  if (!out) throw VesselError(path + ": cannot open for writing");
  out.precision(std::numeric_limits<double>::max_digits10);
  const Eigen::Index n = t.points.rows();
  out << "# vtk DataFile Version 3.0\n" << title << "\nASCII\nDATASET POLYDATA\nPOINTS " << n << " double\n";
  for (Eigen::Index i = 0; i < n; ++i) out << t.points(i, 0) << ' ' << t.points(i, 1) << ' ' << t.points(i, 2) << "\n";
  out << "LINES " << t.segments.rows() << ' ' << 3 * t.segments.rows() << "\n";
  for (Eigen::Index s = 0; s < t.segments.rows(); ++s) out << "2 " << t.segments(s, 0) << ' ' << t.segments(s, 1) << "\n";
  out << "POINT_DATA " << n << "\n";
  for (const auto& [name, values] : {std::pair<const char*, const Eigen::VectorXd*>{"radius", &t.radius},
                                     {"wall_thickness", &t.wall_thickness}}) {
    out << "SCALARS " << name << " double 1\nLOOKUP_TABLE default\n";
    for (Eigen::Index i = 0; i < n; ++i) out << (*values)[i] << "\n";
  }
  if (!out) throw VesselError(path + ": write failed");
}

}  // namespace liver_sim
