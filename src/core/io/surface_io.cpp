// Readers and writers of triangle surfaces: STL, OBJ, PLY, legacy VTK polydata.
#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <vector>

#include "byte_cursor.h"
#include "liver_sim/io/file_names.h"
#include "liver_sim/io/surface_io.h"
#include "vtk_polydata.h"

namespace liver_sim {
namespace {

// Vertices and polygons as read, before the fan split and the index check.
struct RawSurface {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<long long> offsets{0};
  std::vector<long long> corners;
  void add_polygon() { offsets.push_back(static_cast<long long>(corners.size())); }
};

SurfaceMesh finish_surface(const std::string& origin, const RawSurface& raw, double scale) {
  SurfaceMesh s;
  const long long n = static_cast<long long>(raw.vertices.size());
  if (n > std::numeric_limits<int>::max()) throw MeshError(origin + ": too many vertices");
  s.V.resize(n, 3);
  for (long long i = 0; i < n; ++i) {
    if (!raw.vertices[i].allFinite())
      throw MeshError(origin + ": vertex " + std::to_string(i) + " has a non-finite coordinate");
    s.V.row(i) = scale * raw.vertices[i].transpose();
  }
  std::vector<std::array<int, 3>> triangles;
  for (size_t p = 0; p + 1 < raw.offsets.size(); ++p) {
    const long long begin = raw.offsets[p], k = raw.offsets[p + 1] - begin;
    if (k < 3) throw MeshError(origin + ": polygon " + std::to_string(p) + " has " + std::to_string(k) + " corners");
    for (long long j = 0; j < k; ++j)
      if (raw.corners[begin + j] < 0 || raw.corners[begin + j] >= n)
        throw MeshError(origin + ": polygon " + std::to_string(p) + " refers to vertex " +
                        std::to_string(raw.corners[begin + j]) + " out of range (" + std::to_string(n) + " vertices)");
    for (long long j = 1; j + 1 < k; ++j)
      triangles.push_back({static_cast<int>(raw.corners[begin]), static_cast<int>(raw.corners[begin + j]),
                           static_cast<int>(raw.corners[begin + j + 1])});
  }
  if (triangles.empty()) throw MeshError(origin + ": no triangles in the file");
  if (triangles.size() > static_cast<size_t>(std::numeric_limits<int>::max()))
    throw MeshError(origin + ": too many triangles");
  s.F.resize(static_cast<Eigen::Index>(triangles.size()), 3);
  for (size_t t = 0; t < triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) s.F(t, k) = triangles[t][k];
  return s;
}

// ---- STL

void read_stl_binary(ByteCursor& in, RawSurface& raw) {
  in.set_binary(true);
  in.bytes(80, "the header");
  const auto n = static_cast<long long>(in.binary(4, false, false, false, "the triangle count"));
  in.mark();
  if (static_cast<unsigned long long>(n) * 50 != in.remaining())
    in.fail("binary STL: the header announces " + std::to_string(n) + " triangles (" + std::to_string(84 + 50 * n) +
            " bytes) but the file has " + std::to_string(84 + in.remaining()) + " bytes");
  raw.vertices.reserve(static_cast<size_t>(3 * n));
  for (long long t = 0; t < n; ++t) {
    in.bytes(12, "a normal");
    for (int k = 0; k < 3; ++k) {
      Eigen::Vector3d p;
      for (int c = 0; c < 3; ++c) p[c] = in.binary(4, true, true, false, "a vertex");
      raw.corners.push_back(static_cast<long long>(raw.vertices.size()));
      raw.vertices.push_back(p);
    }
    raw.add_polygon();
    in.bytes(2, "an attribute");
  }
}

void read_stl_ascii(ByteCursor& in, RawSurface& raw) {
  in.expect("solid");
  in.line();  // name
  for (std::string key = in.token("facet or endsolid"); key != "endsolid"; key = in.token("facet or endsolid")) {
    if (key != "facet") in.fail("expected facet or endsolid, got '" + key + "'");
    in.expect("normal");
    for (int c = 0; c < 3; ++c) in.number("normal component");
    in.expect("outer");
    in.expect("loop");
    for (std::string v = in.token("vertex or endloop"); v != "endloop"; v = in.token("vertex or endloop")) {
      if (v != "vertex") in.fail("expected vertex or endloop, got '" + v + "'");
      Eigen::Vector3d p;
      for (int c = 0; c < 3; ++c) p[c] = in.number("coordinate");
      raw.corners.push_back(static_cast<long long>(raw.vertices.size()));
      raw.vertices.push_back(p);
    }
    raw.add_polygon();
    in.expect("endfacet");
  }
}

// ASCII when the file starts with "solid" and its first kilobyte is text, unless its size is
// exactly what a binary header announces (binary files may start with "solid" too).
bool stl_is_ascii(const std::string& bytes) {
  if (bytes.size() >= 84) {
    uint32_t n;
    std::memcpy(&n, bytes.data() + 80, 4);  // little-endian hosts only, as everything ROS 1 runs on
    if (84 + 50 * static_cast<unsigned long long>(n) == bytes.size()) return false;
  }
  const size_t start = bytes.find_first_not_of(" \t\r\n");
  if (start == std::string::npos || bytes.compare(start, 5, "solid") != 0) return false;
  for (size_t i = 0; i < std::min<size_t>(bytes.size(), 1024); ++i) {
    const auto c = static_cast<unsigned char>(bytes[i]);
    if (c < 32 && !std::isspace(c)) return false;
    if (c > 126) return false;
  }
  return true;
}

// ---- OBJ

void read_obj(ByteCursor& in, RawSurface& raw) {
  while (in.remaining() > 0) {
    std::string l = in.line();
    const size_t hash = l.find('#');
    if (hash != std::string::npos) l.resize(hash);
    std::istringstream words(l);
    std::string key;
    if (!(words >> key)) continue;
    if (key == "v") {
      Eigen::Vector3d p;
      for (int c = 0; c < 3; ++c) {
        std::string w;
        char* end = nullptr;
        if (!(words >> w) || (p[c] = std::strtod(w.c_str(), &end), end != w.c_str() + w.size()))
          in.fail("v: expected 3 coordinates");
      }
      raw.vertices.push_back(p);
    } else if (key == "f") {
      std::string corner;
      while (words >> corner) {
        // v, v/vt, v//vn or v/vt/vn: the vertex is the first number; negative counts from the end.
        char* end = nullptr;
        errno = 0;
        const long long k = std::strtoll(corner.c_str(), &end, 10);
        if (end == corner.c_str() || (*end != '\0' && *end != '/') || k == 0 || errno == ERANGE)
          in.fail("f: bad vertex reference '" + corner + "'");
        raw.corners.push_back(k > 0 ? k - 1 : static_cast<long long>(raw.vertices.size()) + k);
      }
      raw.add_polygon();
    }
    // Texture coordinates, normals, groups, materials, lines: not part of the surface.
  }
}

// ---- PLY

struct PlyProperty {
  std::string name;
  std::string type;        // value type, or the index type of a list
  std::string count_type;  // list length type; empty for a scalar property
};
struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> properties;
};

int ply_type_size(ByteCursor& in, const std::string& t, bool* floating, bool* is_signed) {
  struct Type {
    const char* name;
    int size;
    bool floating, is_signed;
  };
  static const Type types[] = {{"char", 1, false, true},    {"int8", 1, false, true},     {"uchar", 1, false, false},
                               {"uint8", 1, false, false},  {"short", 2, false, true},    {"int16", 2, false, true},
                               {"ushort", 2, false, false}, {"uint16", 2, false, false},  {"int", 4, false, true},
                               {"int32", 4, false, true},   {"uint", 4, false, false},    {"uint32", 4, false, false},
                               {"float", 4, true, true},    {"float32", 4, true, true},   {"double", 8, true, true},
                               {"float64", 8, true, true}};
  for (const Type& type : types)
    if (t == type.name) {
      *floating = type.floating;
      *is_signed = type.is_signed;
      return type.size;
    }
  in.fail("unknown PLY type '" + t + "'");
}

void read_ply(ByteCursor& in, RawSurface& raw) {
  in.expect("ply");
  in.expect("format");
  const std::string format = in.token("a PLY format");
  if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian")
    in.fail("unknown PLY format '" + format + "'");
  in.line();  // version
  const bool binary = format != "ascii", big_endian = format == "binary_big_endian";
  std::vector<PlyElement> elements;
  for (;;) {
    const std::string key = in.token("end_header");
    if (key == "end_header") break;
    if (key == "comment" || key == "obj_info") {
      in.line();
    } else if (key == "element") {
      PlyElement e;
      e.name = in.token("element name");
      e.count = in.count("element count", 1LL << 40);
      elements.push_back(e);
    } else if (key == "property") {
      if (elements.empty()) in.fail("property before any element");
      PlyProperty p;
      p.type = in.token("property type");
      if (p.type == "list") {
        p.count_type = in.token("list count type");
        p.type = in.token("list index type");
      }
      p.name = in.token("property name");
      elements.back().properties.push_back(p);
    } else {
      in.fail("unexpected '" + key + "' in the PLY header");
    }
  }
  if (binary) {
    in.skip_line_end();
    in.set_binary(true);
  }
  auto value = [&](const std::string& type, const char* what) {
    bool floating, is_signed;
    const int size = ply_type_size(in, type, &floating, &is_signed);
    if (binary) return in.binary(size, floating, is_signed, big_endian, what);
    return in.number(what);
  };
  for (const PlyElement& e : elements) {
    const bool vertex = e.name == "vertex", face = e.name == "face";
    // Each element takes at least one byte: a count beyond the data left is a lie.
    if (e.count > static_cast<long long>(in.remaining()) + 1)
      in.fail("element " + e.name + ": " + std::to_string(e.count) + " items cannot fit in the rest of the file");
    int xyz[3] = {-1, -1, -1};
    for (size_t k = 0; k < e.properties.size(); ++k)
      for (int c = 0; c < 3; ++c)
        if (vertex && e.properties[k].count_type.empty() && e.properties[k].name == std::string(1, "xyz"[c])) xyz[c] = static_cast<int>(k);
    if (vertex && (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0)) in.fail("element vertex has no x, y and z properties");
    for (long long i = 0; i < e.count; ++i) {
      Eigen::Vector3d p = Eigen::Vector3d::Zero();
      for (size_t k = 0; k < e.properties.size(); ++k) {
        const PlyProperty& prop = e.properties[k];
        if (prop.count_type.empty()) {
          const double v = value(prop.type, "a property value");
          for (int c = 0; c < 3; ++c)
            if (xyz[c] == static_cast<int>(k)) p[c] = v;
          continue;
        }
        const double n = value(prop.count_type, "a list length");
        if (n < 0 || n != std::floor(n) || n > static_cast<double>(in.remaining()) + 1) in.fail("bad list length");
        const bool corners = face && (prop.name == "vertex_indices" || prop.name == "vertex_index");
        for (long long j = 0; j < static_cast<long long>(n); ++j) {
          const double v = value(prop.type, "a list entry");
          if (corners) raw.corners.push_back(v == std::floor(v) && std::abs(v) < 9e15 ? static_cast<long long>(v) : -1);
        }
        if (corners) raw.add_polygon();
      }
      if (vertex) raw.vertices.push_back(p);
    }
  }
}

// ---- legacy VTK

void read_vtk_surface(const std::string& bytes, const std::string& origin, RawSurface& raw) {
  const VtkPolyData data = read_vtk_polydata(bytes, origin);
  for (Eigen::Index i = 0; i < data.points.rows(); ++i) raw.vertices.push_back(data.points.row(i).transpose());
  const VtkCells& polygons = data.polygons;
  for (long long c = 0; c < polygons.size(); ++c) {
    for (long long j = polygons.offsets[c]; j < polygons.offsets[c + 1]; ++j) raw.corners.push_back(polygons.connectivity[j]);
    raw.add_polygon();
  }
  // A strip a b c d ... is the triangles (a b c), (c b d), (c d e), ... : every second one
  // reversed so that all keep the strip's orientation.
  const VtkCells& strips = data.strips;
  for (long long c = 0; c < strips.size(); ++c)
    for (long long j = strips.offsets[c]; j + 2 < strips.offsets[c + 1]; ++j) {
      const long long* q = &strips.connectivity[j];
      const bool odd = (j - strips.offsets[c]) % 2 == 1;
      raw.corners.insert(raw.corners.end(), {odd ? q[1] : q[0], odd ? q[0] : q[1], q[2]});
      raw.add_polygon();
    }
}

// ---- writers

template <typename T>
void put(std::ostream& out, T value, bool big_endian) {
  char b[sizeof(T)];
  std::memcpy(b, &value, sizeof(T));
  if (big_endian) std::reverse(b, b + sizeof(T));
  out.write(b, sizeof(T));
}

void write_stl(std::ostream& out, const SurfaceMesh& s, bool binary) {
  auto normal = [&](Eigen::Index t) {
    const Eigen::Vector3d a = s.V.row(s.F(t, 0)), b = s.V.row(s.F(t, 1)), c = s.V.row(s.F(t, 2));
    return (b - a).cross(c - a).normalized().eval();
  };
  if (binary) {
    std::string header = "liver_sim surface";
    header.resize(80, ' ');
    out << header;
    put(out, static_cast<uint32_t>(s.F.rows()), false);
    for (Eigen::Index t = 0; t < s.F.rows(); ++t) {
      const Eigen::Vector3d n = normal(t);
      for (int c = 0; c < 3; ++c) put(out, static_cast<float>(n[c]), false);
      for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) put(out, static_cast<float>(s.V(s.F(t, k), c)), false);
      put(out, uint16_t{0}, false);
    }
    return;
  }
  out << "solid liver_sim\n";
  for (Eigen::Index t = 0; t < s.F.rows(); ++t) {
    const Eigen::Vector3d n = normal(t);
    out << "facet normal " << n[0] << ' ' << n[1] << ' ' << n[2] << "\n outer loop\n";
    for (int k = 0; k < 3; ++k)
      out << "  vertex " << s.V(s.F(t, k), 0) << ' ' << s.V(s.F(t, k), 1) << ' ' << s.V(s.F(t, k), 2) << "\n";
    out << " endloop\nendfacet\n";
  }
  out << "endsolid liver_sim\n";
}

void write_obj(std::ostream& out, const SurfaceMesh& s) {
  out << "# liver_sim surface\n";
  for (Eigen::Index i = 0; i < s.V.rows(); ++i) out << "v " << s.V(i, 0) << ' ' << s.V(i, 1) << ' ' << s.V(i, 2) << "\n";
  for (Eigen::Index t = 0; t < s.F.rows(); ++t)
    out << "f " << s.F(t, 0) + 1 << ' ' << s.F(t, 1) + 1 << ' ' << s.F(t, 2) + 1 << "\n";
}

void write_ply(std::ostream& out, const SurfaceMesh& s, bool binary) {
  out << "ply\nformat " << (binary ? "binary_little_endian" : "ascii") << " 1.0\ncomment liver_sim surface\n"
      << "element vertex " << s.V.rows() << "\nproperty double x\nproperty double y\nproperty double z\n"
      << "element face " << s.F.rows() << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (Eigen::Index i = 0; i < s.V.rows(); ++i) {
    if (binary)
      for (int c = 0; c < 3; ++c) put(out, s.V(i, c), false);
    else
      out << s.V(i, 0) << ' ' << s.V(i, 1) << ' ' << s.V(i, 2) << "\n";
  }
  for (Eigen::Index t = 0; t < s.F.rows(); ++t) {
    if (binary) {
      put(out, uint8_t{3}, false);
      for (int k = 0; k < 3; ++k) put(out, static_cast<int32_t>(s.F(t, k)), false);
    } else {
      out << "3 " << s.F(t, 0) << ' ' << s.F(t, 1) << ' ' << s.F(t, 2) << "\n";
    }
  }
}

void write_vtk_polydata(std::ostream& out, const SurfaceMesh& s, bool binary) {
  out << "# vtk DataFile Version 3.0\nliver_sim surface\n" << (binary ? "BINARY" : "ASCII")
      << "\nDATASET POLYDATA\nPOINTS " << s.V.rows() << " double\n";
  for (Eigen::Index i = 0; i < s.V.rows(); ++i) {
    if (binary)
      for (int c = 0; c < 3; ++c) put(out, s.V(i, c), true);
    else
      out << s.V(i, 0) << ' ' << s.V(i, 1) << ' ' << s.V(i, 2) << "\n";
  }
  out << (binary ? "\n" : "") << "POLYGONS " << s.F.rows() << ' ' << 4 * s.F.rows() << "\n";
  for (Eigen::Index t = 0; t < s.F.rows(); ++t) {
    if (binary) {
      put(out, int32_t{3}, true);
      for (int k = 0; k < 3; ++k) put(out, static_cast<int32_t>(s.F(t, k)), true);
    } else {
      out << "3 " << s.F(t, 0) << ' ' << s.F(t, 1) << ' ' << s.F(t, 2) << "\n";
    }
  }
  if (binary) out << "\n";
}

}  // namespace

SurfaceFormat surface_format(const std::string& path) {
  const std::string e = file_extension(path);
  if (e == "stl") return SurfaceFormat::Stl;
  if (e == "obj") return SurfaceFormat::Obj;
  if (e == "ply") return SurfaceFormat::Ply;
  if (e == "vtk") return SurfaceFormat::Vtk;
  throw MeshError(path + ": unknown surface format (expected .stl, .obj, .ply or .vtk)");
}

SurfaceMesh read_surface(const std::string& path, double scale) {
  const SurfaceFormat format = surface_format(path);
  std::ifstream file(path, std::ios::binary);
  if (!file) throw MeshError(path + ": cannot open");
  std::ostringstream bytes;
  bytes << file.rdbuf();
  return read_surface(bytes.str(), format, path, scale);
}

SurfaceMesh read_surface(const std::string& bytes, SurfaceFormat format, const std::string& origin, double scale) {
  if (!std::isfinite(scale) || scale <= 0) throw MeshError(origin + ": scale must be finite and > 0");
  if (bytes.find_first_not_of(" \t\r\n") == std::string::npos) throw MeshError(origin + ": empty file");
  RawSurface raw;
  try {
    ByteCursor in(bytes, origin);
    switch (format) {
      case SurfaceFormat::Stl:
        stl_is_ascii(bytes) ? read_stl_ascii(in, raw) : read_stl_binary(in, raw);
        break;
      case SurfaceFormat::Obj: read_obj(in, raw); break;
      case SurfaceFormat::Ply: read_ply(in, raw); break;
      case SurfaceFormat::Vtk: read_vtk_surface(bytes, origin, raw); break;
    }
  } catch (const FormatError& e) {
    throw MeshError(e.what());
  } catch (const std::bad_alloc&) {
    throw MeshError(origin + ": too large to read");
  } catch (const std::length_error&) {
    throw MeshError(origin + ": too large to read");
  }
  return finish_surface(origin, raw, scale);
}

void write_surface(const std::string& path, const SurfaceMesh& surface, SurfaceEncoding encoding) {
  const SurfaceFormat format = surface_format(path);
  std::ofstream out(path, std::ios::binary);
  if (!out) throw MeshError(path + ": cannot open for writing");
  out.precision(std::numeric_limits<double>::max_digits10);
  const bool binary = encoding == SurfaceEncoding::Binary;
  switch (format) {
    case SurfaceFormat::Stl: write_stl(out, surface, binary); break;
    case SurfaceFormat::Obj: write_obj(out, surface); break;
    case SurfaceFormat::Ply: write_ply(out, surface, binary); break;
    case SurfaceFormat::Vtk: write_vtk_polydata(out, surface, binary); break;
  }
  if (!out) throw MeshError(path + ": write failed");
}

}  // namespace liver_sim
