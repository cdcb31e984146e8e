// Readers and writers of tetrahedral meshes: Gmsh 1.0 / 2.2 / 4.1 ASCII and legacy VTK.
#include <array>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "liver_sim/io/mesh_io.h"
#include "text_tokens.h"

namespace liver_sim {
namespace {

using Tokens = TextTokens<MeshError>;

// Nodes by file id and tetrahedra by node id, as read; turned into a TetMesh by finish_mesh().
struct RawMesh {
  std::vector<long long> node_id;
  std::vector<Eigen::Vector3d> node;
  std::vector<std::array<long long, 4>> tet;
  std::vector<size_t> tet_line;  // for messages
};

// Nodes per element of the Gmsh element types (index = type); 0 = unknown.
int gmsh_nodes_per_element(long long type) {
  static const int n[] = {0, 2, 3, 4, 4, 8, 6, 5, 3, 6, 9, 10, 27, 18, 14, 1, 8, 20, 15, 13};
  return (type >= 1 && type < static_cast<long long>(sizeof(n) / sizeof(n[0]))) ? n[type] : 0;
}

Eigen::Vector3d read_point(Tokens& in) {
  Eigen::Vector3d p;
  for (int c = 0; c < 3; ++c) p[c] = in.number("coordinate");
  return p;
}

// Reads the k node ids of one element and keeps it when it is a tetrahedron (Gmsh type 4).
void read_element_nodes(Tokens& in, long long type, long long k, RawMesh& raw) {
  std::array<long long, 4> t{};
  for (long long j = 0; j < k; ++j) {
    const long long v = in.integer("node id");
    if (j < 4) t[j] = v;
  }
  if (type != 4) return;
  if (k != 4) in.fail("tetrahedron with " + std::to_string(k) + " nodes");
  raw.tet.push_back(t);
  raw.tet_line.push_back(in.line());
}

// Nodes per element of a Gmsh type, or a clear error for a type that cannot be skipped.
int gmsh_element_size(Tokens& in, long long type) {
  const int k = gmsh_nodes_per_element(type);
  if (k == 0) in.fail("unknown element type " + std::to_string(type));
  return k;
}

void read_gmsh1(Tokens& in, RawMesh& raw) {
  // "$NOD" was consumed by the format detection.
  const long long nn = in.count("node count");
  for (long long i = 0; i < nn; ++i) {
    raw.node_id.push_back(in.integer("node id"));
    raw.node.push_back(read_point(in));
  }
  in.expect("$ENDNOD");
  in.expect("$ELM");
  const long long ne = in.count("element count");
  for (long long i = 0; i < ne; ++i) {
    in.integer("element id");
    const long long type = in.integer("element type");
    in.integer("physical region");
    in.integer("elementary region");
    read_element_nodes(in, type, in.count("node count of element", 64), raw);
  }
  in.expect("$ENDELM");
}

// Gmsh 2.2 and 4.1 share their section structure; only the $Nodes and $Elements bodies differ.
template <typename Nodes, typename Elements>
void read_gmsh_sections(Tokens& in, Nodes read_nodes, Elements read_elements) {
  while (!in.at_end()) {
    const std::string section = in.next("a section");
    if (section == "$Nodes") {
      read_nodes();
      in.expect("$EndNodes");
    } else if (section == "$Elements") {
      read_elements();
      in.expect("$EndElements");
    } else if (!section.empty() && section[0] == '$') {
      in.skip_section(section);
    } else {
      in.fail("expected a section, got '" + section + "'");
    }
  }
}

void read_gmsh2(Tokens& in, RawMesh& raw) {
  read_gmsh_sections(
      in,
      [&] {
        const long long nn = in.count("node count");
        for (long long i = 0; i < nn; ++i) {
          raw.node_id.push_back(in.integer("node id"));
          raw.node.push_back(read_point(in));
        }
      },
      [&] {
        const long long ne = in.count("element count");
        for (long long i = 0; i < ne; ++i) {
          in.integer("element id");
          const long long type = in.integer("element type");
          const int k = gmsh_element_size(in, type);
          const long long tags = in.count("tag count", 64);
          for (long long j = 0; j < tags; ++j) in.integer("tag");
          read_element_nodes(in, type, k, raw);
        }
      });
}

void read_gmsh4(Tokens& in, RawMesh& raw) {
  read_gmsh_sections(
      in,
      [&] {
        const long long blocks = in.count("entity block count");
        in.count("node count");
        in.integer("min node tag");
        in.integer("max node tag");
        for (long long b = 0; b < blocks; ++b) {
          const long long dim = in.integer("entity dimension");
          in.integer("entity tag");
          const long long parametric = in.integer("parametric flag");
          const long long n = in.count("nodes in block");
          for (long long i = 0; i < n; ++i) raw.node_id.push_back(in.integer("node tag"));
          for (long long i = 0; i < n; ++i) {
            raw.node.push_back(read_point(in));
            for (long long u = 0; parametric == 1 && u < dim; ++u) in.number("parametric coordinate");
          }
        }
      },
      [&] {
        const long long blocks = in.count("entity block count");
        in.count("element count");
        in.integer("min element tag");
        in.integer("max element tag");
        for (long long b = 0; b < blocks; ++b) {
          in.integer("entity dimension");
          in.integer("entity tag");
          const long long type = in.integer("element type");
          const int k = gmsh_element_size(in, type);
          const long long n = in.count("elements in block");
          for (long long i = 0; i < n; ++i) {
            in.integer("element tag");
            read_element_nodes(in, type, k, raw);
          }
        }
      });
}

void read_vtk(Tokens& in, RawMesh& raw) {
  in.rest_of_line();  // title
  const std::string encoding = in.next("ASCII");
  if (encoding != "ASCII") in.fail("only ASCII legacy VTK is supported, got '" + encoding + "'");
  in.expect("DATASET");
  const std::string dataset = in.next("UNSTRUCTURED_GRID");
  if (dataset != "UNSTRUCTURED_GRID") in.fail("expected DATASET UNSTRUCTURED_GRID, got '" + dataset + "'");
  std::vector<std::vector<long long>> cells;
  while (!in.at_end()) {
    const std::string key = in.next("a section");
    if (key == "POINTS") {
      const long long n = in.count("point count");
      in.next("data type");
      for (long long i = 0; i < n; ++i) {
        raw.node_id.push_back(i);
        raw.node.push_back(read_point(in));
      }
    } else if (key == "CELLS") {
      const long long n = in.count("cell count");
      in.count("cell list size", std::numeric_limits<long long>::max());
      for (long long i = 0; i < n; ++i) {
        const long long k = in.count("cell size", 1000);
        std::vector<long long> c(k);
        for (auto& v : c) v = in.integer("point index");
        cells.push_back(std::move(c));
      }
    } else if (key == "CELL_TYPES") {
      const long long n = in.count("cell type count");
      if (n != static_cast<long long>(cells.size())) in.fail("CELL_TYPES count differs from CELLS count");
      for (long long i = 0; i < n; ++i) {
        const long long type = in.integer("cell type");
        if (type != 10) continue;  // VTK_TETRA
        if (cells[i].size() != 4) in.fail("tetra cell " + std::to_string(i) + " does not have 4 points");
        raw.tet.push_back({cells[i][0], cells[i][1], cells[i][2], cells[i][3]});
        raw.tet_line.push_back(in.line());
      }
    } else if (key == "POINT_DATA" || key == "CELL_DATA") {
      break;  // attributes follow; the geometry is complete
    } else {
      in.fail("unexpected '" + key + "'");
    }
  }
}

TetMesh finish_mesh(const std::string& path, RawMesh& raw, double scale) {
  if (raw.tet.empty()) throw MeshError(path + ": no tetrahedra in the file");
  std::unordered_map<long long, int> index;
  for (size_t i = 0; i < raw.node_id.size(); ++i)
    if (!index.emplace(raw.node_id[i], static_cast<int>(i)).second)
      throw MeshError(path + ": node id " + std::to_string(raw.node_id[i]) + " defined twice");
  // Keep only nodes used by a tetrahedron, in file order.
  std::vector<int> used(raw.node.size(), -1);
  TetMesh m;
  m.T.resize(raw.tet.size(), 4);
  for (size_t t = 0; t < raw.tet.size(); ++t)
    for (int k = 0; k < 4; ++k) {
      const auto it = index.find(raw.tet[t][k]);
      if (it == index.end())
        throw MeshError(path + ":" + std::to_string(raw.tet_line[t]) + ": tetrahedron " + std::to_string(t) +
                        " uses undefined node " + std::to_string(raw.tet[t][k]));
      used[it->second] = 0;
      m.T(t, k) = it->second;
    }
  int n = 0;
  for (int& u : used)
    if (u == 0) u = n++;
  m.V.resize(n, 3);
  for (size_t i = 0; i < raw.node.size(); ++i)
    if (used[i] >= 0) m.V.row(used[i]) = scale * raw.node[i].transpose();
  for (int t = 0; t < m.T.rows(); ++t)
    for (int k = 0; k < 4; ++k) m.T(t, k) = used[m.T(t, k)];

  // A file whose elements are all negatively oriented follows the other convention.
  bool all_negative = true;
  for (int t = 0; t < m.T.rows() && all_negative; ++t) all_negative = signed_volume(m.V, m.T, t) < 0;
  if (all_negative) m.T.col(2).swap(m.T.col(3));
  validate_mesh(m, path);
  return m;
}

std::ofstream open_for_writing(const std::string& path) {
  std::ofstream out(path);
  if (!out) throw MeshError(path + ": cannot open for writing");
  out.precision(std::numeric_limits<double>::max_digits10);
  return out;
}

}  // namespace

TetMesh read_mesh(const std::string& path, double scale) {
  std::ifstream file(path);
  if (!file) throw MeshError(path + ": cannot open");
  return read_mesh(file, path, scale);
}

TetMesh read_mesh(std::istream& stream, const std::string& path, double scale) {
  if (!std::isfinite(scale) || scale <= 0) throw MeshError(path + ": scale must be finite and > 0");
  Tokens in(path, stream);
  if (in.at_end()) throw MeshError(path + ": empty file");
  RawMesh raw;
  try {
    const std::string first = in.next("a format header");
    if (first == "$NOD") {
      read_gmsh1(in, raw);
    } else if (first == "$MeshFormat") {
      const std::string version = in.next("a version");
      const long long file_type = in.integer("file type");
      in.integer("data size");
      if (file_type != 0) in.fail("binary Gmsh files are not supported; save as ASCII");
      in.expect("$EndMeshFormat");
      if (version.rfind("2.", 0) == 0) {
        read_gmsh2(in, raw);
      } else if (version.rfind("4.1", 0) == 0) {
        read_gmsh4(in, raw);
      } else {
        in.fail("unsupported Gmsh version " + version + " (2.2 or 4.1 ASCII expected)");
      }
    } else if (first == "#") {
      const std::string header = in.rest_of_line();
      if (header.find("vtk DataFile") == std::string::npos) in.fail("unknown format");
      read_vtk(in, raw);
    } else {
      in.fail("unknown format (expected Gmsh $NOD or $MeshFormat, or '# vtk DataFile')");
    }
  } catch (const MeshError&) {
    throw;
  } catch (const std::exception& e) {
    throw MeshError(path + ": " + e.what());
  }
  return finish_mesh(path, raw, scale);
}

void write_gmsh22(const std::string& path, const TetMesh& mesh) {
  std::ofstream out = open_for_writing(path);
  out << "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n" << mesh.V.rows() << "\n";
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i)
    out << i + 1 << ' ' << mesh.V(i, 0) << ' ' << mesh.V(i, 1) << ' ' << mesh.V(i, 2) << "\n";
  out << "$EndNodes\n$Elements\n" << mesh.T.rows() << "\n";
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t)
    out << t + 1 << " 4 2 1 1 " << mesh.T(t, 0) + 1 << ' ' << mesh.T(t, 1) + 1 << ' ' << mesh.T(t, 2) + 1
        << ' ' << mesh.T(t, 3) + 1 << "\n";
  out << "$EndElements\n";
  if (!out) throw MeshError(path + ": write failed");
}

void write_gmsh41(const std::string& path, const TetMesh& mesh) {
  std::ofstream out = open_for_writing(path);
  const auto nv = mesh.V.rows(), nt = mesh.T.rows();
  out << "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n";
  out << "$Nodes\n1 " << nv << " 1 " << nv << "\n3 1 0 " << nv << "\n";
  for (Eigen::Index i = 0; i < nv; ++i) out << i + 1 << "\n";
  for (Eigen::Index i = 0; i < nv; ++i) out << mesh.V(i, 0) << ' ' << mesh.V(i, 1) << ' ' << mesh.V(i, 2) << "\n";
  out << "$EndNodes\n$Elements\n1 " << nt << " 1 " << nt << "\n3 1 4 " << nt << "\n";
  for (Eigen::Index t = 0; t < nt; ++t)
    out << t + 1 << ' ' << mesh.T(t, 0) + 1 << ' ' << mesh.T(t, 1) + 1 << ' ' << mesh.T(t, 2) + 1 << ' '
        << mesh.T(t, 3) + 1 << "\n";
  out << "$EndElements\n";
  if (!out) throw MeshError(path + ": write failed");
}

void write_vtk(const std::string& path, const TetMesh& mesh) {
  std::ofstream out = open_for_writing(path);
  const auto nv = mesh.V.rows(), nt = mesh.T.rows();
  out << "# vtk DataFile Version 3.0\nliver_sim tetrahedral mesh\nASCII\nDATASET UNSTRUCTURED_GRID\n";
  out << "POINTS " << nv << " double\n";
  for (Eigen::Index i = 0; i < nv; ++i) out << mesh.V(i, 0) << ' ' << mesh.V(i, 1) << ' ' << mesh.V(i, 2) << "\n";
  out << "CELLS " << nt << ' ' << 5 * nt << "\n";
  for (Eigen::Index t = 0; t < nt; ++t)
    out << "4 " << mesh.T(t, 0) << ' ' << mesh.T(t, 1) << ' ' << mesh.T(t, 2) << ' ' << mesh.T(t, 3) << "\n";
  out << "CELL_TYPES " << nt << "\n";
  for (Eigen::Index t = 0; t < nt; ++t) out << "10\n";
  if (!out) throw MeshError(path + ": write failed");
}

}  // namespace liver_sim
