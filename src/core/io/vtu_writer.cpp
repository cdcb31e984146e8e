#include "liver_sim/io/vtu_writer.h"

#include <fstream>
#include <limits>
#include <stdexcept>

namespace liver_sim {

void write_vtu(const std::string& path, const TetMesh& mesh, const Eigen::VectorXd& displacement) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot open for writing");
  out.precision(std::numeric_limits<double>::max_digits10);
  const auto nv = mesh.V.rows(), nt = mesh.T.rows();
  out << "<?xml version=\"1.0\"?>\n"
      << "<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
      << "<UnstructuredGrid>\n<Piece NumberOfPoints=\"" << nv << "\" NumberOfCells=\"" << nt << "\">\n"
      << "<PointData Vectors=\"displacement\">\n"
      << "<DataArray type=\"Float64\" Name=\"displacement\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  for (Eigen::Index i = 0; i < nv; ++i)
    out << displacement[3 * i] << ' ' << displacement[3 * i + 1] << ' ' << displacement[3 * i + 2] << '\n';
  out << "</DataArray>\n</PointData>\n<Points>\n"
      << "<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  for (Eigen::Index i = 0; i < nv; ++i)
    out << mesh.V(i, 0) << ' ' << mesh.V(i, 1) << ' ' << mesh.V(i, 2) << '\n';
  out << "</DataArray>\n</Points>\n<Cells>\n"
      << "<DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n";
  for (Eigen::Index e = 0; e < nt; ++e)
    out << mesh.T(e, 0) << ' ' << mesh.T(e, 1) << ' ' << mesh.T(e, 2) << ' ' << mesh.T(e, 3) << '\n';
  out << "</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n";
  for (Eigen::Index e = 0; e < nt; ++e) out << 4 * (e + 1) << '\n';
  out << "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
  for (Eigen::Index e = 0; e < nt; ++e) out << "10\n";  // VTK_TETRA
  out << "</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
  if (!out) throw std::runtime_error(path + ": write failed");
}

}  // namespace liver_sim
