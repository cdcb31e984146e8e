#include "liver_sim/io/label_map_io.h"

#include <zlib.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

#include "byte_cursor.h"

namespace liver_sim {
namespace {

constexpr long long kMaxVoxels = 1LL << 28;

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r"), b = s.find_last_not_of(" \t\r");
  return a == std::string::npos ? "" : s.substr(a, b - a + 1);
}

// The voxels' storage: bytes per value, integer or floating, signed.
struct Storage {
  int size = 0;
  bool floating = false, is_signed = false;
};

// A gzip or zlib stream (several gzip members in a row too) inflated to exactly `expected` bytes.
std::string inflate_exactly(const std::string& in, size_t offset, size_t expected, const std::string& origin) {
  std::string out(expected, '\0');
  z_stream z{};
  if (inflateInit2(&z, 15 + 32) != Z_OK) throw FormatError(origin + ": zlib could not start");
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data() + offset));
  z.avail_in = static_cast<uInt>(std::min<size_t>(in.size() - offset, UINT32_MAX));
  size_t done = 0;
  int status = Z_OK;
  while (done < expected) {
    const size_t chunk = std::min<size_t>(expected - done, 1u << 30);
    z.next_out = reinterpret_cast<Bytef*>(&out[done]);
    z.avail_out = static_cast<uInt>(chunk);
    status = inflate(&z, Z_NO_FLUSH);
    done += chunk - z.avail_out;
    if (status == Z_STREAM_END && done < expected && z.avail_in > 0) {
      inflateReset(&z);  // the next gzip member
      continue;
    }
    if (status != Z_OK) break;
  }
  inflateEnd(&z);
  if (done < expected) {
    const std::string why = status == Z_STREAM_END || status == Z_BUF_ERROR ? "ends early" : "is corrupt";
    throw FormatError(origin + ": the compressed data " + why + " (" + std::to_string(done) + " of " +
                      std::to_string(expected) + " bytes)");
  }
  return out;
}

void check_dims(const Eigen::Array3i& dims, const std::string& origin) {
  if ((dims < 1).any()) throw FormatError(origin + ": a size below 1");
  if (static_cast<double>(dims[0]) * dims[1] * dims[2] > static_cast<double>(kMaxVoxels))
    throw FormatError(origin + ": " + std::to_string(dims[0]) + " x " + std::to_string(dims[1]) + " x " +
                      std::to_string(dims[2]) + " voxels, more than 2^28");
}

// Voxel values from binary data at `data`; each must be a whole number in the int32 range.
void decode(LabelImage& image, const char* data, Storage st, bool big_endian, double slope, double inter,
            const std::string& origin) {
  const size_t n = image.labels.size();
  for (size_t v = 0; v < n; ++v) {
    unsigned char b[8];
    for (int i = 0; i < st.size; ++i) b[i] = static_cast<unsigned char>(data[v * st.size + (big_endian ? st.size - 1 - i : i)]);
    uint64_t u = 0;
    for (int i = st.size - 1; i >= 0; --i) u = (u << 8) | b[i];
    double x;
    if (st.floating) {
      if (st.size == 4) {
        float f;
        const uint32_t u32 = static_cast<uint32_t>(u);
        std::memcpy(&f, &u32, 4);
        x = f;
      } else {
        std::memcpy(&x, &u, 8);
      }
    } else if (!st.is_signed) {
      x = static_cast<double>(u);
    } else {
      const uint64_t sign = uint64_t{1} << (8 * st.size - 1);
      x = st.size == 8 ? static_cast<double>(static_cast<int64_t>(u))
                       : static_cast<double>(static_cast<int64_t>(u ^ sign) - static_cast<int64_t>(sign));
    }
    x = slope * x + inter;
    if (!(std::abs(x) <= 2147483647.0) || x != std::floor(x)) {
      std::ostringstream m;
      m << origin << ": voxel " << v << " holds " << x << ", not a label (a whole number in the int32 range)";
      throw FormatError(m.str());
    }
    image.labels[v] = static_cast<int32_t>(x);
  }
}

void check_geometry(const LabelImage& image, const std::string& origin) {
  const double det = image.axes.determinant();
  if (!image.axes.allFinite() || !image.origin.allFinite() || !std::isfinite(det) || std::abs(det) < 1e-30)
    throw FormatError(origin + ": the voxel axes (direction times spacing) are singular or not finite");
}

// Lengths in the file's unit -> metres.
double unit_scale(const std::string& unit, const std::string& origin) {
  const std::string u = lower(trim(unit));
  if (u.empty() || u == "mm") return 1e-3;
  if (u == "m") return 1.0;
  if (u == "cm") return 1e-2;
  if (u == "um" || u == "micron" || u == "microns") return 1e-6;
  throw FormatError(origin + ": unknown length unit '" + unit + "'");
}

// ---- NIfTI-1: a 348-byte header, then the voxels from vox_offset.
LabelImage read_nifti(const std::string& file, const std::string& origin) {
  std::string inflated;
  const std::string* bytes = &file;
  if (file.size() >= 2 && static_cast<unsigned char>(file[0]) == 0x1f && static_cast<unsigned char>(file[1]) == 0x8b) {
    // The header first, then the whole file once its size is known.
    const std::string head = inflate_exactly(file, 0, 348, origin);
    ByteCursor probe(head, origin);
    probe.set_binary(true);
    bool big = false;
    const int32_t sz = static_cast<int32_t>(probe.binary(4, false, true, false, "sizeof_hdr"));
    if (sz != 348) big = true;
    ByteCursor c(head, origin);
    c.set_binary(true);
    c.bytes(40, "header");
    double dims = 1;
    const int nd = static_cast<int>(c.binary(2, false, true, big, "dim"));
    for (int i = 1; i <= 7; ++i) {
      const double d = c.binary(2, false, true, big, "dim");
      if (i <= nd && d > 0) dims *= d;
    }
    c.bytes(72 - 56, "header");
    const double bitpix = c.binary(2, false, true, big, "bitpix");
    c.bytes(108 - 74, "header");
    const double offset = c.binary(4, true, true, big, "vox_offset");
    const double total = std::max(offset, 348.0) + dims * std::max(bitpix, 8.0) / 8;
    if (!(total < static_cast<double>(kMaxVoxels) * 8 + 1e6))
      throw FormatError(origin + ": the header announces " + std::to_string(total) + " bytes of data");
    inflated = inflate_exactly(file, 0, static_cast<size_t>(total), origin);
    bytes = &inflated;
  }
  ByteCursor c(*bytes, origin);
  c.set_binary(true);
  const int32_t size_le = static_cast<int32_t>(c.binary(4, false, true, false, "sizeof_hdr"));
  bool big = false;
  if (size_le != 348) {
    ByteCursor b(*bytes, origin);
    b.set_binary(true);
    const int32_t size_be = static_cast<int32_t>(b.binary(4, false, true, true, "sizeof_hdr"));
    if (size_le == 540 || size_be == 540) throw FormatError(origin + ": NIfTI-2 is not read; save as NIfTI-1");
    if (size_be != 348) throw FormatError(origin + ": not a NIfTI-1 file (sizeof_hdr " + std::to_string(size_le) + ")");
    big = true;
  }
  auto at = [&](size_t offset, int size, bool floating, bool is_signed, const char* what) {
    ByteCursor f(*bytes, origin);
    f.set_binary(true);
    f.bytes(offset, what);
    return f.binary(size, floating, is_signed, big, what);
  };
  ByteCursor m(*bytes, origin);
  m.set_binary(true);
  m.bytes(344, "header");
  const std::string magic(m.bytes(4, "magic"), 4);
  if (magic == std::string("ni1\0", 4)) throw FormatError(origin + ": a .hdr/.img pair; give a single-file .nii");
  if (magic != std::string("n+1\0", 4)) throw FormatError(origin + ": not a NIfTI-1 file (magic)");
  const int nd = static_cast<int>(at(40, 2, false, true, "dim[0]"));
  if (nd < 3 || nd > 7) throw FormatError(origin + ": " + std::to_string(nd) + " dimensions; a label map has 3");
  LabelImage image;
  for (int i = 1; i <= nd; ++i) {
    const int d = static_cast<int>(at(40 + 2 * i, 2, false, true, "dim"));
    if (i <= 3) image.dims[i - 1] = d;
    else if (d != 1) throw FormatError(origin + ": dimension " + std::to_string(i) + " has size " + std::to_string(d) + "; a label map has 3");
  }
  check_dims(image.dims, origin);
  const int datatype = static_cast<int>(at(70, 2, false, true, "datatype"));
  static const std::map<int, Storage> types = {{2, {1, false, false}},   {4, {2, false, true}},   {8, {4, false, true}},
                                               {16, {4, true, true}},    {64, {8, true, true}},   {256, {1, false, true}},
                                               {512, {2, false, false}}, {768, {4, false, false}}, {1024, {8, false, true}},
                                               {1280, {8, false, false}}};
  const auto type = types.find(datatype);
  if (type == types.end()) throw FormatError(origin + ": datatype " + std::to_string(datatype) + " is not a label type");
  Eigen::Vector3d pixdim;
  for (int i = 0; i < 3; ++i) pixdim[i] = at(80 + 4 * i, 4, true, true, "pixdim");
  const double qfac = at(76, 4, true, true, "pixdim[0]") < 0 ? -1.0 : 1.0;
  const double offset = at(108, 4, true, true, "vox_offset");
  double slope = at(112, 4, true, true, "scl_slope"), inter = at(116, 4, true, true, "scl_inter");
  if (slope == 0 || !std::isfinite(slope) || !std::isfinite(inter)) slope = 1, inter = 0;  // the standard: unscaled
  const int units = static_cast<int>(at(123, 1, false, false, "xyzt_units")) & 7;
  const double scale = units == 1 ? 1.0 : units == 3 ? 1e-6 : 1e-3;  // 0 (unknown): millimetres
  const int qcode = static_cast<int>(at(252, 2, false, true, "qform_code"));
  const int scode = static_cast<int>(at(254, 2, false, true, "sform_code"));
  Eigen::Matrix3d axes_ras;
  Eigen::Vector3d origin_ras;
  if (scode > 0) {  // the sform, as nibabel and 3D Slicer prefer it when set
    for (int r = 0; r < 3; ++r) {
      for (int k = 0; k < 3; ++k) axes_ras(r, k) = at(280 + 16 * r + 4 * k, 4, true, true, "srow");
      origin_ras[r] = at(280 + 16 * r + 12, 4, true, true, "srow");
    }
    image.orientation_source = "sform";
  } else if (qcode > 0) {
    const double b = at(256, 4, true, true, "quatern_b"), cq = at(260, 4, true, true, "quatern_c"),
                 d = at(264, 4, true, true, "quatern_d");
    const double a = std::sqrt(std::max(0.0, 1.0 - (b * b + cq * cq + d * d)));
    const Eigen::Matrix3d R = Eigen::Quaterniond(a, b, cq, d).normalized().toRotationMatrix();
    if ((pixdim.array() <= 0).any()) throw FormatError(origin + ": pixdim must be > 0 with a qform");
    axes_ras = R * Eigen::Vector3d(pixdim[0], pixdim[1], qfac * pixdim[2]).asDiagonal();
    for (int r = 0; r < 3; ++r) origin_ras[r] = at(268 + 4 * r, 4, true, true, "qoffset");
    image.orientation_source = "qform";
  } else {  // no orientation: NIfTI's method 1, the spacing alone
    if ((pixdim.array() <= 0).any()) throw FormatError(origin + ": no qform, no sform and no positive pixdim");
    axes_ras = pixdim.asDiagonal();
    origin_ras.setZero();
    image.orientation_source = "pixdim only (no qform or sform)";
  }
  const Eigen::Vector3d ras_to_lps(-1, -1, 1);
  image.axes = scale * ras_to_lps.asDiagonal() * axes_ras;
  image.origin = scale * ras_to_lps.asDiagonal() * origin_ras;
  check_geometry(image, origin);
  if (!(offset >= 348) || offset > static_cast<double>(bytes->size()))
    throw FormatError(origin + ": vox_offset " + std::to_string(offset) + " outside the file");
  const size_t n = static_cast<size_t>(image.dims.cast<long long>().prod());
  const size_t need = n * static_cast<size_t>(type->second.size);
  const size_t start = static_cast<size_t>(offset);
  if (bytes->size() - start < need)
    throw FormatError(origin + ": the file ends inside the voxel data (" + std::to_string(need) + " bytes needed, " +
                      std::to_string(bytes->size() - start) + " left)");
  image.labels.resize(n);
  decode(image, bytes->data() + start, type->second, big, slope, inter, origin);
  return image;
}

// ---- NRRD: "NRRD000N", "field: value" and "key:=value" lines, a blank line, the data.
std::vector<double> tuple(const std::string& text, const std::string& origin) {
  std::string t = trim(text);
  if (t.size() < 2 || t.front() != '(' || t.back() != ')') throw FormatError(origin + ": expected a vector (a,b,c), got '" + text + "'");
  std::vector<double> v;
  std::stringstream s(t.substr(1, t.size() - 2));
  std::string item;
  while (std::getline(s, item, ',')) {
    char* end = nullptr;
    const std::string x = trim(item);
    v.push_back(std::strtod(x.c_str(), &end));
    if (x.empty() || end != x.c_str() + x.size() || !std::isfinite(v.back()))
      throw FormatError(origin + ": '" + text + "' is not a vector of numbers");
  }
  return v;
}

Storage nrrd_type(const std::string& name, const std::string& origin) {
  static const std::map<std::string, Storage> types = {
      {"signed char", {1, false, true}}, {"int8", {1, false, true}}, {"int8_t", {1, false, true}},
      {"uchar", {1, false, false}}, {"unsigned char", {1, false, false}}, {"uint8", {1, false, false}},
      {"uint8_t", {1, false, false}}, {"short", {2, false, true}}, {"short int", {2, false, true}},
      {"signed short", {2, false, true}}, {"signed short int", {2, false, true}}, {"int16", {2, false, true}},
      {"int16_t", {2, false, true}}, {"ushort", {2, false, false}}, {"unsigned short", {2, false, false}},
      {"unsigned short int", {2, false, false}}, {"uint16", {2, false, false}}, {"uint16_t", {2, false, false}},
      {"int", {4, false, true}}, {"signed int", {4, false, true}}, {"int32", {4, false, true}},
      {"int32_t", {4, false, true}}, {"uint", {4, false, false}}, {"unsigned int", {4, false, false}},
      {"uint32", {4, false, false}}, {"uint32_t", {4, false, false}}, {"longlong", {8, false, true}},
      {"long long", {8, false, true}}, {"long long int", {8, false, true}}, {"signed long long", {8, false, true}},
      {"signed long long int", {8, false, true}}, {"int64", {8, false, true}}, {"int64_t", {8, false, true}},
      {"ulonglong", {8, false, false}}, {"unsigned long long", {8, false, false}},
      {"unsigned long long int", {8, false, false}}, {"uint64", {8, false, false}}, {"uint64_t", {8, false, false}},
      {"float", {4, true, true}}, {"double", {8, true, true}}};
  const auto it = types.find(lower(trim(name)));
  if (it == types.end()) throw FormatError(origin + ": type '" + name + "' is not a label type");
  return it->second;
}

LabelImage read_nrrd(const std::string& file, const std::string& origin) {
  if (file.compare(0, 7, "NRRD000") != 0 || file.size() < 9) throw FormatError(origin + ": not a NRRD file (magic)");
  std::map<std::string, std::string> field;
  std::map<int, std::pair<std::string, int>> segments;  // SegmentN -> name, label value
  size_t pos = file.find('\n');
  if (pos == std::string::npos) throw FormatError(origin + ": no header");
  ++pos;
  for (int line = 2;; ++line) {
    if (pos >= file.size()) throw FormatError(origin + ": the header has no end (a blank line)");
    const size_t end = std::min(file.find('\n', pos), file.size());
    std::string l = file.substr(pos, end - pos);
    pos = std::min(end + 1, file.size());
    if (!l.empty() && l.back() == '\r') l.pop_back();
    if (l.empty()) break;
    if (l[0] == '#') continue;
    const std::string where = origin + ":" + std::to_string(line);
    if (const size_t kv = l.find(":="); kv != std::string::npos) {
      const std::string key = l.substr(0, kv), value = l.substr(kv + 2);
      int n = -1;
      char what[32] = {0};
      if (std::sscanf(key.c_str(), "Segment%d_%31s", &n, what) == 2 && n >= 0 && n < 100000) {
        if (std::string(what) == "Name") segments[n].first = value;
        if (std::string(what) == "LabelValue") segments[n].second = std::atoi(value.c_str());
      }
      continue;
    }
    const size_t colon = l.find(": ");
    if (colon == std::string::npos) throw FormatError(where + ": expected 'field: value', got '" + l + "'");
    field[lower(trim(l.substr(0, colon)))] = trim(l.substr(colon + 2));
  }
  auto get = [&](const std::string& name) {
    const auto it = field.find(name);
    return it == field.end() ? std::string() : it->second;
  };
  if (!get("data file").empty() || !get("datafile").empty())
    throw FormatError(origin + ": detached data (a .nhdr header); give a .nrrd with the data attached");
  if (!get("byte skip").empty() && get("byte skip") != "0") throw FormatError(origin + ": byte skip is not supported");
  if (!get("line skip").empty() && get("line skip") != "0") throw FormatError(origin + ": line skip is not supported");
  const Storage st = nrrd_type(get("type"), origin);
  std::vector<long long> sizes;
  {
    std::istringstream s(get("sizes"));
    long long v;
    while (s >> v) sizes.push_back(v);
  }
  const int dimension = std::atoi(get("dimension").c_str());
  if (dimension != static_cast<int>(sizes.size())) throw FormatError(origin + ": dimension and sizes disagree");
  // 3D Slicer's one-layer segmentations may come with a leading axis of size 1.
  const bool leading_layer = dimension == 4 && sizes[0] == 1;
  if (dimension == 4 && sizes[0] > 1)
    throw FormatError(origin + ": " + std::to_string(sizes[0]) + " layers (overlapping segments); export the segment as a label map");
  if (dimension != 3 && !leading_layer) throw FormatError(origin + ": " + std::to_string(dimension) + " dimensions; a label map has 3");
  LabelImage image;
  for (int i = 0; i < 3; ++i) image.dims[i] = static_cast<int>(std::clamp<long long>(sizes[i + leading_layer], -1, 1 << 30));
  check_dims(image.dims, origin);

  const std::string space = lower(get("space"));
  Eigen::Vector3d sign(1, 1, 1);
  if (space == "right-anterior-superior" || space == "ras") sign << -1, -1, 1;
  else if (space == "left-anterior-superior" || space == "las") sign << 1, -1, 1;
  else if (!space.empty() && space != "left-posterior-superior" && space != "lps")
    throw FormatError(origin + ": space '" + get("space") + "' is not a patient frame (LPS, RAS, LAS)");
  double scale = 1e-3;
  if (const std::string units = get("space units"); !units.empty()) {
    std::istringstream s(units);
    std::string u, first;
    while (s >> u) {
      u.erase(std::remove(u.begin(), u.end(), '"'), u.end());
      if (first.empty()) first = u;
      if (u != first) throw FormatError(origin + ": the axes have different units");
    }
    scale = unit_scale(first, origin);
  }
  if (!space.empty()) {
    std::istringstream s(get("space directions"));
    std::string item;
    std::vector<std::vector<double>> dirs;
    while (s >> item)
      if (item != "none") dirs.push_back(tuple(item, origin));
    if (dirs.size() != 3 || dirs[0].size() != 3 || dirs[1].size() != 3 || dirs[2].size() != 3)
      throw FormatError(origin + ": expected three space directions of 3 numbers");
    for (int k = 0; k < 3; ++k) image.axes.col(k) = Eigen::Vector3d(dirs[k][0], dirs[k][1], dirs[k][2]);
    if (const std::string o = get("space origin"); !o.empty()) {
      const std::vector<double> v = tuple(o, origin);
      if (v.size() != 3) throw FormatError(origin + ": expected a space origin of 3 numbers");
      image.origin = Eigen::Vector3d(v[0], v[1], v[2]);
    }
    image.orientation_source = "space directions (" + get("space") + ")";
  } else {
    std::istringstream s(get("spacings"));
    std::vector<double> sp;
    std::string item;
    while (s >> item) sp.push_back(item == "nan" ? 1.0 : std::strtod(item.c_str(), nullptr));
    if (sp.size() != sizes.size()) throw FormatError(origin + ": no space directions and no spacings for every axis");
    image.axes = Eigen::Vector3d(sp[leading_layer], sp[leading_layer + 1], sp[leading_layer + 2]).asDiagonal();
    image.orientation_source = "spacings only (no space: taken as LPS)";
  }
  image.axes = scale * sign.asDiagonal() * image.axes;
  image.origin = scale * sign.asDiagonal() * image.origin;
  check_geometry(image, origin);

  const size_t n = static_cast<size_t>(image.dims.cast<long long>().prod());
  image.labels.resize(n);
  const std::string encoding = lower(get("encoding"));
  const bool big = lower(get("endian")) == "big";
  if (encoding == "raw" || encoding == "gzip" || encoding == "gz") {
    std::string inflated;
    const char* data = nullptr;
    const size_t need = n * static_cast<size_t>(st.size);
    if (encoding == "raw") {
      if (file.size() - pos < need)
        throw FormatError(origin + ": the file ends inside the voxel data (" + std::to_string(need) + " bytes needed, " +
                          std::to_string(file.size() - pos) + " left)");
      data = file.data() + pos;
    } else {
      inflated = inflate_exactly(file, pos, need, origin);
      data = inflated.data();
    }
    decode(image, data, st, big, 1.0, 0.0, origin);
  } else if (encoding == "text" || encoding == "txt" || encoding == "ascii") {
    const std::string body = file.substr(pos);
    ByteCursor c(body, origin);
    for (size_t v = 0; v < n; ++v) {
      const double x = c.number("a voxel value");
      if (!(std::abs(x) <= 2147483647.0) || x != std::floor(x))
        throw FormatError(origin + ": voxel " + std::to_string(v) + " is not a label (a whole number)");
      image.labels[v] = static_cast<int32_t>(x);
    }
  } else {
    throw FormatError(origin + ": encoding '" + get("encoding") + "' is not read (raw, gzip, text)");
  }
  for (const auto& [n_segment, s] : segments) image.segments.push_back(s);
  return image;
}

}  // namespace

LabelMapFormat label_map_format(const std::string& path) {
  const std::string p = lower(path);
  auto ends = [&](const std::string& e) { return p.size() >= e.size() && p.compare(p.size() - e.size(), e.size(), e) == 0; };
  if (ends(".nii") || ends(".nii.gz")) return LabelMapFormat::Nifti;
  if (ends(".nrrd")) return LabelMapFormat::Nrrd;
  throw MeshError(path + ": not a label map (.nii, .nii.gz, .nrrd, .seg.nrrd)");
}

bool is_label_map(const std::string& path) {
  try {
    label_map_format(path);
    return true;
  } catch (const MeshError&) {
    return false;
  }
}

LabelImage read_label_map(const std::string& bytes, LabelMapFormat format, const std::string& origin) {
  try {
    if (bytes.empty()) throw FormatError(origin + ": empty file");
    return format == LabelMapFormat::Nifti ? read_nifti(bytes, origin) : read_nrrd(bytes, origin);
  } catch (const FormatError& e) {
    throw MeshError(e.what());
  }
}

LabelImage read_label_map(const std::string& path) {
  const LabelMapFormat format = label_map_format(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw MeshError(path + ": cannot open");
  std::ostringstream s;
  s << in.rdbuf();
  return read_label_map(s.str(), format, path);
}

}  // namespace liver_sim
