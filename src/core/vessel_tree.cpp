#include "liver_sim/vessel_tree.h"

#include <yaml-cpp/yaml.h>

#include <fstream>
#include <numeric>
#include <sstream>
#include <vector>

#include "text_tokens.h"

namespace liver_sim {
namespace {

using Tokens = TextTokens<VesselError>;
constexpr long long kMaxNodes = 10000000;

std::string extension(const std::string& path) {
  const size_t dot = path.rfind('.');
  std::string ext = dot == std::string::npos ? "" : path.substr(dot + 1);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

void read_scalars(Tokens& in, long long n, Eigen::VectorXd& out) {
  const std::string type = in.next("data type");
  (void)type;
  const std::string next = in.next("LOOKUP_TABLE or a value");
  if (next != "LOOKUP_TABLE") {
    // The optional component count ("1") came first.
    if (next != "1") in.fail("only 1-component scalars are supported, got '" + next + "'");
    in.expect("LOOKUP_TABLE");
  }
  in.next("lookup table name");
  out.resize(n);
  for (long long i = 0; i < n; ++i) out[i] = in.number("scalar value");
}

// Union-find root with path halving.
int root(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

}  // namespace

VesselTree read_vessel_vtk(std::istream& stream, const std::string& origin, double scale) {
  Tokens in(origin, stream);
  in.expect("#");
  in.rest_of_line();  // "vtk DataFile Version x.y"
  in.rest_of_line();  // title
  const std::string encoding = in.next("ASCII");
  if (encoding != "ASCII") in.fail("only ASCII legacy VTK is supported, got '" + encoding + "'");
  in.expect("DATASET");
  const std::string dataset = in.next("POLYDATA");
  if (dataset != "POLYDATA") in.fail("expected DATASET POLYDATA, got '" + dataset + "'");
  VesselTree t;
  std::vector<Eigen::Vector2i> segments;
  long long n = -1;
  bool point_data = false;
  while (!in.at_end()) {
    const std::string key = in.next("a section");
    if (key == "POINTS") {
      if (n >= 0) in.fail("POINTS given twice");
      n = in.count("point count", kMaxNodes);
      in.next("data type");
      t.points.resize(n, 3);
      for (long long i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) t.points(i, c) = scale * in.number("coordinate");
    } else if (key == "LINES") {
      const long long lines = in.count("line count", kMaxNodes);
      in.count("line list size", 2 * kMaxNodes);
      for (long long l = 0; l < lines; ++l) {
        const long long k = in.count("polyline size", kMaxNodes);
        if (k < 2) in.fail("polyline " + std::to_string(l) + " has fewer than 2 points");
        long long prev = in.integer("point index");
        for (long long j = 1; j < k; ++j) {
          const long long cur = in.integer("point index");
          if (prev < 0 || cur < 0 || prev >= n || cur >= n)
            in.fail("polyline " + std::to_string(l) + " refers to a point out of range");
          segments.emplace_back(static_cast<int>(prev), static_cast<int>(cur));
          prev = cur;
        }
      }
    } else if (key == "POINT_DATA") {
      if (in.count("point data count", kMaxNodes) != n) in.fail("POINT_DATA count differs from POINTS count");
      point_data = true;
    } else if (key == "SCALARS" && point_data) {
      const std::string name = in.next("array name");
      if (name == "radius") {
        read_scalars(in, n, t.radius);
        t.radius *= scale;
      } else if (name == "wall_thickness") {
        read_scalars(in, n, t.wall_thickness);
        t.wall_thickness *= scale;
      } else {
        Eigen::VectorXd ignored;
        read_scalars(in, n, ignored);
      }
    } else {
      in.fail("unexpected '" + key + "'");
    }
  }
  if (n < 0) throw VesselError(origin + ": no POINTS");
  if (t.radius.size() != n) throw VesselError(origin + ": no point array 'radius'");
  if (t.wall_thickness.size() != n) throw VesselError(origin + ": no point array 'wall_thickness'");
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

VesselTree read_vessel_tree(const std::string& path, double scale) {
  std::ifstream in(path);
  if (!in) throw VesselError(path + ": cannot open");
  const std::string ext = extension(path);
  if (ext == "vtk") return read_vessel_vtk(in, path, scale);
  if (ext != "yaml" && ext != "yml") throw VesselError(path + ": unknown vessel format (expected .vtk, .yaml or .yml)");
  std::stringstream text;
  text << in.rdbuf();
  return read_vessel_yaml(text.str(), path, scale);
}

void validate_vessel_tree(const VesselTree& t, const std::string& origin) {
  auto fail = [&](const std::string& message) { throw VesselError(origin + ": " + message); };
  const int n = static_cast<int>(t.points.rows());
  if (n < 2 || t.segments.rows() < 1) fail("a vessel tree needs at least 2 nodes and 1 segment");
  if (t.radius.size() != n || t.wall_thickness.size() != n) fail("radius and wall thickness must be given per node");
  for (int i = 0; i < n; ++i) {
    const std::string node = "node " + std::to_string(i);
    if (!t.points.row(i).allFinite()) fail(node + ": coordinates are not finite");
    if (!std::isfinite(t.radius[i]) || t.radius[i] <= 0) fail(node + ": radius must be > 0");
    if (!std::isfinite(t.wall_thickness[i]) || t.wall_thickness[i] <= 0) fail(node + ": wall thickness must be > 0");
    if (t.wall_thickness[i] > t.radius[i])
      fail(node + ": wall thickness " + std::to_string(t.wall_thickness[i]) + " m exceeds the radius " +
           std::to_string(t.radius[i]) + " m");
  }
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  std::vector<char> used(n, 0);
  for (int s = 0; s < t.segments.rows(); ++s) {
    const int a = t.segments(s, 0), b = t.segments(s, 1);
    const std::string seg = "segment " + std::to_string(s) + " (" + std::to_string(a) + "-" + std::to_string(b) + ")";
    if (a < 0 || b < 0 || a >= n || b >= n) fail(seg + ": node index out of range");
    if (a == b) fail(seg + ": joins a node to itself");
    if ((t.points.row(a) - t.points.row(b)).norm() <= 1e-9 * std::max(t.radius[a], t.radius[b]))
      fail(seg + ": zero length");
    const int ra = root(parent, a), rb = root(parent, b);
    if (ra == rb) fail(seg + ": closes a cycle (a vessel tree has none)");
    parent[ra] = rb;
    used[a] = used[b] = 1;
  }
  for (int i = 0; i < n; ++i)
    if (!used[i]) fail("node " + std::to_string(i) + ": belongs to no segment");
}

}  // namespace liver_sim
