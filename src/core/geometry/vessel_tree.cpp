#include "liver_sim/geometry/vessel_tree.h"

#include <numeric>
#include <sstream>
#include <vector>

namespace liver_sim {
namespace {

// Union-find root with path halving.
int root(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

}  // namespace

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
