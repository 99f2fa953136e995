// The XDMF 3 sidecar of a field file: light XML that points ParaView at the HDF5 datasets.
#include <sstream>
#include <stdexcept>

#include "io_detail.hpp"

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

std::string xdmf_document(std::string_view h5_file_name, int dim, std::size_t nodes, std::size_t cells,
                          const std::vector<std::pair<std::string, int>>& fields) {
  if (dim != 2 && dim != 3) {
    throw std::invalid_argument("xdmf_document: XDMF sidecars need dimension 2 or 3, got " + std::to_string(dim));
  }
  const std::string file = xml_escape(h5_file_name);
  const int per_cell = dim + 1;
  std::ostringstream x;
  x << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    << "<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n"
    << "<Xdmf Version=\"3.0\" xmlns:xi=\"http://www.w3.org/2001/XInclude\">\n"
    << "  <Domain>\n"
    << "    <Grid Name=\"lmeform\" GridType=\"Uniform\">\n"
    << "      <Topology TopologyType=\"" << (dim == 2 ? "Triangle" : "Tetrahedron") << "\" NumberOfElements=\""
    << cells << "\" NodesPerElement=\"" << per_cell << "\">\n"
    << "        <DataItem Dimensions=\"" << cells << ' ' << per_cell
    << "\" NumberType=\"Int\" Precision=\"4\" Format=\"HDF\">" << file << ":/cells</DataItem>\n"
    << "      </Topology>\n"
    << "      <Geometry GeometryType=\"" << (dim == 2 ? "XY" : "XYZ") << "\">\n"
    << "        <DataItem Dimensions=\"" << nodes << ' ' << dim
    << "\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">" << file << ":/nodes</DataItem>\n"
    << "      </Geometry>\n";
  for (const auto& [name, components] : fields) {
    const std::string escaped = xml_escape(name);
    x << "      <Attribute Name=\"" << escaped << "\" AttributeType=\"" << attribute_type(components)
      << "\" Center=\"Node\">\n"
      << "        <DataItem Dimensions=\"" << nodes;
    if (components > 1) x << ' ' << components;
    x << "\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">" << file << ":/fields/" << escaped
      << "</DataItem>\n"
      << "      </Attribute>\n";
  }
  x << "    </Grid>\n"
    << "  </Domain>\n"
    << "</Xdmf>\n";
  return x.str();
}

}  // namespace lmeform::io_detail
