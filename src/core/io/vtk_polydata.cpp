#include "vtk_polydata.h"

#include <cmath>

namespace liver_sim {
namespace {

// A legacy VTK data type: bytes per value in a binary file, floating or integer, signed.
struct ValueType {
  int size = 0;
  bool floating = false;
  bool is_signed = true;
};

ValueType value_type(ByteCursor& in, const std::string& name) {
  static const std::map<std::string, ValueType> types = {
      {"unsigned_char", {1, false, false}}, {"char", {1, false, true}},
      {"unsigned_short", {2, false, false}}, {"short", {2, false, true}},
      {"unsigned_int", {4, false, false}}, {"int", {4, false, true}},
      {"unsigned_long", {8, false, false}}, {"long", {8, false, true}},
      {"vtkIdType", {8, false, true}},       {"float", {4, true, true}},
      {"double", {8, true, true}},           {"vtktypeint8", {1, false, true}},
      {"vtktypeuint8", {1, false, false}},   {"vtktypeint16", {2, false, true}},
      {"vtktypeuint16", {2, false, false}},  {"vtktypeint32", {4, false, true}},
      {"vtktypeuint32", {4, false, false}},  {"vtktypeint64", {8, false, true}},
      {"vtktypeuint64", {8, false, false}},  {"vtktypefloat32", {4, true, true}},
      {"vtktypefloat64", {8, true, true}}};
  const auto it = types.find(name);
  if (it == types.end()) in.fail("unsupported data type '" + name + "'");
  return it->second;
}

class PolyDataReader {
 public:
  PolyDataReader(const std::string& data, const std::string& origin) : in_(data, origin) {}

  VtkPolyData read() {
    const std::string header = in_.line();
    if (header.rfind("# vtk DataFile", 0) != 0) in_.fail("not a legacy VTK file (expected '# vtk DataFile')");
    in_.line();  // title
    const std::string encoding = in_.token("ASCII or BINARY");
    if (encoding != "ASCII" && encoding != "BINARY") in_.fail("expected ASCII or BINARY, got '" + encoding + "'");
    binary_ = encoding == "BINARY";
    in_.expect("DATASET");
    const std::string dataset = in_.token("POLYDATA");
    if (dataset != "POLYDATA") in_.fail("expected DATASET POLYDATA, got '" + dataset + "'");
    while (!in_.at_end()) section(in_.token());
    return std::move(out_);
  }

 private:
  void section(const std::string& key) {
    if (key == "POINTS") {
      if (out_.has_points) in_.fail("POINTS given twice");
      const long long n = in_.count("point count", max_values(3));
      std::vector<double> v;
      values(value_type(in_, in_.token("data type")), 3 * n, "POINTS", v);
      out_.points = Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(v.data(), n, 3);
      out_.has_points = true;
    } else if (key == "VERTICES" || key == "LINES" || key == "POLYGONS" || key == "TRIANGLE_STRIPS") {
      VtkCells& cells = key == "VERTICES" ? out_.vertices
                        : key == "LINES"  ? out_.lines
                        : key == "POLYGONS" ? out_.polygons
                                            : out_.strips;
      read_cells(key, cells);
    } else if (key == "POINT_DATA" || key == "CELL_DATA") {
      const long long n = in_.count(key == "POINT_DATA" ? "point data count" : "cell data count", max_values(1));
      if (key == "POINT_DATA" && n != out_.points.rows()) in_.fail("POINT_DATA count differs from POINTS count");
      point_data_ = key == "POINT_DATA";
      tuples_ = n;
    } else if (key == "SCALARS") {
      const std::string name = in_.token("array name");
      const ValueType type = value_type(in_, in_.token("data type"));
      long long components = 1;
      if (in_.peek() != "LOOKUP_TABLE") components = in_.count("component count", 4);
      if (in_.peek() == "LOOKUP_TABLE") {
        in_.token();
        in_.token("lookup table name");
      }
      attribute(name, type, components);
    } else if (key == "VECTORS" || key == "NORMALS" || key == "TENSORS") {
      const std::string name = in_.token("array name");
      attribute(name, value_type(in_, in_.token("data type")), key == "TENSORS" ? 9 : 3);
    } else if (key == "TEXTURE_COORDINATES") {
      const std::string name = in_.token("array name");
      const long long dim = in_.count("texture dimension", 3);
      attribute(name, value_type(in_, in_.token("data type")), dim);
    } else if (key == "COLOR_SCALARS") {
      const std::string name = in_.token("array name");
      const long long components = in_.count("component count", 4);
      // Binary colour scalars are unsigned bytes, ASCII ones floats in [0, 1].
      attribute(name, binary_ ? ValueType{1, false, false} : ValueType{8, true, true}, components);
    } else if (key == "LOOKUP_TABLE") {
      in_.token("lookup table name");
      const long long n = in_.count("lookup table size", max_values(4));
      std::vector<double> ignored;
      values(binary_ ? ValueType{1, false, false} : ValueType{8, true, true}, 4 * n, "LOOKUP_TABLE", ignored);
    } else if (key == "FIELD") {
      in_.token("field name");
      const long long arrays = in_.count("array count", 10000);
      for (long long a = 0; a < arrays; ++a) {
        const std::string name = in_.token("array name");
        if (name == "NULL_ARRAY") continue;
        const long long components = in_.count("component count", 10000);
        const long long n = in_.count("tuple count", max_values(components == 0 ? 1 : components));
        const ValueType type = value_type(in_, in_.token("data type"));
        std::vector<double> v;
        values(type, components * n, "FIELD array", v);
        if (point_data_ && n == out_.points.rows() && components > 0) store(name, v, components);
      }
    } else if (key == "METADATA") {
      // Key/value information up to an empty line (VTK 8.1 and later), not needed here.
      in_.line();
      while (in_.remaining() > 0 && !blank(in_.line())) {
      }
    } else {
      in_.fail("unexpected '" + key + "'");
    }
  }

  static bool blank(const std::string& line) {
    return line.find_first_not_of(" \t\r") == std::string::npos;
  }
  void attribute(const std::string& name, const ValueType& type, long long components) {
    std::vector<double> v;
    values(type, components * tuples_, "attribute data", v);
    if (point_data_ && components > 0) store(name, v, components);
  }

  void store(const std::string& name, const std::vector<double>& v, long long components) {
    const long long n = static_cast<long long>(v.size()) / components;
    out_.point_arrays[name] =
        Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(v.data(), n, components);
  }

  // Most values `count` values of at least `per` bytes each could fill in the data left.
  long long max_values(long long per) const {
    return static_cast<long long>(in_.remaining() / static_cast<size_t>(std::max(1LL, per)) + 1);
  }

  void values(const ValueType& type, long long count, const char* what, std::vector<double>& out) {
    // ASCII values take at least 2 bytes (a digit and a separator), binary ones their size.
    const long long per = binary_ ? type.size : 2;
    if (count < 0 || count > static_cast<long long>(in_.remaining() / static_cast<size_t>(per)) + 1)
      in_.fail(std::string(what) + ": " + std::to_string(count) + " values cannot fit in the rest of the file");
    out.resize(static_cast<size_t>(count));
    if (binary_) {
      in_.skip_line_end();
      in_.set_binary(true);
      for (double& x : out) x = in_.binary(type.size, type.floating, type.is_signed, true, what);
      in_.set_binary(false);
      for (const double x : out)
        if (!std::isfinite(x)) in_.fail(std::string(what) + ": a value is not finite");
    } else {
      for (double& x : out) x = in_.number(what);
    }
  }

  long long index(double v, const char* what) {
    if (v != std::floor(v) || v < 0 || v >= 9.0e15) in_.fail(std::string(what) + " is not a valid index");
    return static_cast<long long>(v);
  }

  void read_cells(const std::string& key, VtkCells& cells) {
    if (!cells.connectivity.empty()) in_.fail(key + " given twice");
    const long long a = in_.count("cell count", max_values(1));
    const long long b = in_.count("cell list size", max_values(1));
    std::vector<double> v;
    if (in_.peek() == "OFFSETS") {  // file version 5.1: offsets, then connectivity
      in_.token();
      values(value_type(in_, in_.token("offset type")), a, "OFFSETS", v);
      cells.offsets.clear();
      for (const double x : v) cells.offsets.push_back(index(x, "offset"));
      in_.expect("CONNECTIVITY");
      values(value_type(in_, in_.token("connectivity type")), b, "CONNECTIVITY", v);
      for (const double x : v) cells.connectivity.push_back(index(x, "point index"));
      if (cells.offsets.empty() || cells.offsets.front() != 0 || cells.offsets.back() != b)
        in_.fail(key + ": OFFSETS must start at 0 and end at the connectivity size");
      for (size_t c = 1; c < cells.offsets.size(); ++c)
        if (cells.offsets[c] < cells.offsets[c - 1]) in_.fail(key + ": OFFSETS decrease at " + std::to_string(c));
    } else {  // classic: per cell, its size then its point indices
      values(binary_ ? ValueType{4, false, true} : ValueType{8, true, true}, b, key.c_str(), v);
      size_t at = 0;
      for (long long c = 0; c < a; ++c) {
        if (at >= v.size()) in_.fail(key + ": the list ends before cell " + std::to_string(c));
        const long long k = index(v[at++], "cell size");
        if (k > static_cast<long long>(v.size() - at)) in_.fail(key + ": cell " + std::to_string(c) + " runs past the list");
        for (long long j = 0; j < k; ++j) cells.connectivity.push_back(index(v[at++], "point index"));
        cells.offsets.push_back(static_cast<long long>(cells.connectivity.size()));
      }
      if (at != v.size()) in_.fail(key + ": the list size does not match its cells");
    }
    const long long n = out_.points.rows();
    for (long long c = 0; c < cells.size(); ++c)
      for (long long j = cells.offsets[c]; j < cells.offsets[c + 1]; ++j)
        if (cells.connectivity[j] >= n)
          in_.fail(key + ": cell " + std::to_string(c) + " refers to point " + std::to_string(cells.connectivity[j]) +
                   " out of range (" + std::to_string(n) + " points)");
  }

  ByteCursor in_;
  VtkPolyData out_;
  bool binary_ = false;
  bool point_data_ = false;
  long long tuples_ = 0;
};

}  // namespace

VtkPolyData read_vtk_polydata(const std::string& data, const std::string& origin) {
  return PolyDataReader(data, origin).read();
}

}  // namespace liver_sim
