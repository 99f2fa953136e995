// The XDMF 3 sidecar of a field file: light XML that points ParaView at the HDF5 datasets.
#include <sstream>
#include <stdexcept>

#include "io_detail.hpp"
#include "lmeform/output.hpp"

#include <cstdio>

namespace lmeform::io_detail {
namespace {

std::string xml_escape(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default: out += c;
    }
  }
  return out;
}

// XDMF attribute types by component count; anything else is a general Matrix (N x c).
const char* attribute_type(int components) {
  switch (components) {
    case 1: return "Scalar";
    case 3: return "Vector";
    case 6: return "Tensor6";
    case 9: return "Tensor";
    default: return "Matrix";
  }
}

}  // namespace

namespace {

/// One <Grid> over the datasets of a write_field_hdf5 file; `time` adds a <Time> (a time series step).
void write_grid(std::ostringstream& x, std::string_view h5_file_name, int dim, std::size_t nodes, std::size_t cells,
                const std::vector<std::pair<std::string, int>>& fields, const std::string& name, const double* time,
                std::string_view indent) {
  if (dim != 2 && dim != 3) {
    throw std::invalid_argument("xdmf: XDMF needs dimension 2 or 3, got " + std::to_string(dim));
  }
  const std::string file = xml_escape(h5_file_name);
  const int per_cell = dim + 1;
  x << indent << "<Grid Name=\"" << xml_escape(name) << "\" GridType=\"Uniform\">\n";
  if (time != nullptr) {
    std::ostringstream t;
    t.precision(17);
    t << *time;
    x << indent << "  <Time Value=\"" << t.str() << "\"/>\n";
  }
  x << indent << "  <Topology TopologyType=\"" << (dim == 2 ? "Triangle" : "Tetrahedron") << "\" NumberOfElements=\""
    << cells << "\" NodesPerElement=\"" << per_cell << "\">\n"
    << indent << "    <DataItem Dimensions=\"" << cells << ' ' << per_cell
    << "\" NumberType=\"Int\" Precision=\"4\" Format=\"HDF\">" << file << ":/cells</DataItem>\n"
    << indent << "  </Topology>\n"
    << indent << "  <Geometry GeometryType=\"" << (dim == 2 ? "XY" : "XYZ") << "\">\n"
    << indent << "    <DataItem Dimensions=\"" << nodes << ' ' << dim
    << "\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">" << file << ":/nodes</DataItem>\n"
    << indent << "  </Geometry>\n";
  for (const auto& [field, components] : fields) {
    const std::string escaped = xml_escape(field);
    x << indent << "  <Attribute Name=\"" << escaped << "\" AttributeType=\"" << attribute_type(components)
      << "\" Center=\"Node\">\n"
      << indent << "    <DataItem Dimensions=\"" << nodes;
    if (components > 1) x << ' ' << components;
    x << "\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">" << file << ":/fields/" << escaped
      << "</DataItem>\n"
      << indent << "  </Attribute>\n";
  }
  x << indent << "</Grid>\n";
}

const char* const kHeader =
    "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    "<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n"
    "<Xdmf Version=\"3.0\" xmlns:xi=\"http://www.w3.org/2001/XInclude\">\n"
    "  <Domain>\n";
const char* const kFooter = "  </Domain>\n</Xdmf>\n";

}  // namespace

std::string xdmf_document(std::string_view h5_file_name, int dim, std::size_t nodes, std::size_t cells,
                          const std::vector<std::pair<std::string, int>>& fields) {
  std::ostringstream x;
  x << kHeader;
  write_grid(x, h5_file_name, dim, nodes, cells, fields, "lmeform", nullptr, "    ");
  x << kFooter;
  return x.str();
}

std::string xdmf_time_series_document(const std::vector<XdmfStep>& steps) {
  std::ostringstream x;
  x << kHeader << "    <Grid Name=\"series\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const XdmfStep& s = steps[i];
    write_grid(x, s.h5_file, s.dim, s.nodes, s.cells, s.fields, "step " + std::to_string(i), &s.time, "      ");
  }
  x << "    </Grid>\n" << kFooter;
  return x.str();
}

}  // namespace lmeform::io_detail

namespace lmeform {

void write_xdmf_time_series(const std::filesystem::path& path, std::span<const TimeSeriesStep> steps) {
  std::vector<io_detail::XdmfStep> items;
  items.reserve(steps.size());
  for (const TimeSeriesStep& s : steps) items.push_back({s.time, s.h5_file.generic_string(), s.dim, s.nodes, s.cells, s.fields});
  write_text_atomically(path, io_detail::xdmf_time_series_document(items));
}

std::filesystem::path TimeSeriesWriter::file_of(int step) const {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "_%06d.h5", step);
  return std::filesystem::path("series") / (name_ + buffer);
}

void TimeSeriesWriter::write(double time, int step, const NodeSet& nodes, const BackgroundCells& cells, const FieldViews& fields,
                             const OutputAttributes& attributes) {
  const std::filesystem::path file = file_of(step);
  std::filesystem::create_directories(directory_ / "series");
  write_field_hdf5(directory_ / file, nodes, cells, fields, attributes);
  add_step(time, file, nodes, cells, fields, true);
}

void TimeSeriesWriter::write(MPI_Comm comm, double time, int step, const NodeSet& nodes, const BackgroundCells& cells,
                             const DistributedFields& local, const OutputAttributes& attributes) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  const std::filesystem::path file = file_of(step);
  std::error_code made;
  if (rank == 0) std::filesystem::create_directories(directory_ / "series", made);
  // A folder that cannot be made fails the collective write on every rank, naming the file.
  MPI_Barrier(comm);
  write_field_hdf5(comm, directory_ / file, nodes, cells, local, attributes);
  add_step(time, file, nodes, cells, local.fields, rank == 0);
}

void TimeSeriesWriter::add_step(double time, const std::filesystem::path& file, const NodeSet& nodes, const BackgroundCells& cells,
                                const FieldViews& fields, bool write_collection) {
  TimeSeriesStep entry;
  entry.time = time;
  entry.h5_file = file;
  entry.dim = nodes.dim;
  entry.nodes = nodes.size();
  entry.cells = cells.size();
  for (const auto& [field, view] : fields) entry.fields.emplace_back(field, view.components);
  steps_.push_back(std::move(entry));
  if (write_collection && nodes.dim >= 2) write_xdmf_time_series(directory_ / (name_ + ".xmf"), steps_);
}

}  // namespace lmeform
