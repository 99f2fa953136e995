// Field files: nodes, background cells and nodal fields in HDF5 (+ XDMF sidecar), and reading them back.
#include <hdf5.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "io_detail.hpp"
#include "lmeform/output.hpp"
#include "lmeform/resource_usage.hpp"

namespace lmeform {
namespace {

constexpr const char* kFormatName = "lmeform-fields";
constexpr std::int64_t kFormatVersion = 1;

// ---- HDF5 plumbing -------------------------------------------------------------------------------

// Turns HDF5's automatic error printing off for one call of ours and restores it afterwards:
// errors are reported through our exceptions instead of on stderr.
class QuietHdf5Errors {
 public:
  QuietHdf5Errors() {
    H5Eget_auto2(H5E_DEFAULT, &func_, &data_);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
  QuietHdf5Errors(const QuietHdf5Errors&) = delete;
  QuietHdf5Errors& operator=(const QuietHdf5Errors&) = delete;
  ~QuietHdf5Errors() { H5Eset_auto2(H5E_DEFAULT, func_, data_); }

 private:
  H5E_auto2_t func_ = nullptr;
  void* data_ = nullptr;
};

herr_t collect_error(unsigned n, const H5E_error2_t* err, void* data) {
  auto* lines = static_cast<std::vector<std::string>*>(data);
  if (err != nullptr && err->desc != nullptr) {
    (void)n;
    lines->emplace_back(err->desc);
  }
  return 0;
}

// The current HDF5 error stack as one line: the outermost description and the innermost one
// (which carries errno and the OS message for file errors). Call right after the failing call.
std::string hdf5_error() {
  std::vector<std::string> lines;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD, collect_error, &lines);
  H5Eclear2(H5E_DEFAULT);
  if (lines.empty()) return "HDF5 error (no details)";
  if (lines.size() == 1 || lines.front() == lines.back()) return "HDF5: " + lines.front();
  return "HDF5: " + lines.front() + " (" + lines.back() + ")";
}

// An HDF5 identifier closed on scope exit; close() reports a failing close.
class Handle {
 public:
  using Closer = herr_t (*)(hid_t);
  Handle() = default;
  Handle(hid_t id, Closer closer) noexcept : id_(id), closer_(closer) {}
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  Handle(Handle&& other) noexcept : id_(std::exchange(other.id_, H5I_INVALID_HID)), closer_(other.closer_) {}
  Handle& operator=(Handle&&) = delete;
  ~Handle() {
    if (id_ >= 0 && closer_ != nullptr) closer_(id_);
  }
  [[nodiscard]] hid_t get() const noexcept { return id_; }
  herr_t close() noexcept {
    const hid_t id = std::exchange(id_, H5I_INVALID_HID);
    return id >= 0 && closer_ != nullptr ? closer_(id) : 0;
  }

 private:
  hid_t id_ = H5I_INVALID_HID;
  Closer closer_ = nullptr;
};

// Throws "<context>: <what>: <HDF5 error>" when an HDF5 call failed.
struct Checker {
  std::string context;

  [[noreturn]] void fail(const std::string& what) const {
    throw std::runtime_error(context + ": " + what + ": " + hdf5_error());
  }
  Handle handle(hid_t id, Handle::Closer closer, const std::string& what) const {
    if (id < 0) fail(what);
    return {id, closer};
  }
  void status(herr_t status, const std::string& what) const {
    if (status < 0) fail(what);
  }
};

// ---- writing -------------------------------------------------------------------------------------

void write_dataset(const Checker& check, hid_t parent, const std::string& name, hid_t file_type, hid_t mem_type,
                   const std::vector<hsize_t>& dims, const void* data) {
  const Handle space =
      check.handle(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr), H5Sclose,
                   "cannot create the dataspace of " + name);
  const Handle set = check.handle(H5Dcreate2(parent, name.c_str(), file_type, space.get(), H5P_DEFAULT,
                                             H5P_DEFAULT, H5P_DEFAULT),
                                  H5Dclose, "cannot create dataset " + name);
  hsize_t count = 1;
  for (const hsize_t d : dims) count *= d;
  if (count > 0) {
    check.status(H5Dwrite(set.get(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), "cannot write dataset " + name);
  }
}

void write_attribute(const Checker& check, hid_t object, const std::string& name, const OutputAttribute& value) {
  const Handle space = check.handle(H5Screate(H5S_SCALAR), H5Sclose, "cannot create a scalar dataspace");
  const std::string what = "cannot write attribute '" + name + "'";
  if (const auto* d = std::get_if<double>(&value)) {
    const Handle a = check.handle(
        H5Acreate2(object, name.c_str(), H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose, what);
    check.status(H5Awrite(a.get(), H5T_NATIVE_DOUBLE, d), what);
  } else if (const auto* i = std::get_if<std::int64_t>(&value)) {
    const Handle a = check.handle(
        H5Acreate2(object, name.c_str(), H5T_STD_I64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose, what);
    check.status(H5Awrite(a.get(), H5T_NATIVE_INT64, i), what);
  } else {
    const std::string& s = std::get<std::string>(value);
    const Handle type = check.handle(H5Tcopy(H5T_C_S1), H5Tclose, what);
    check.status(H5Tset_size(type.get(), H5T_VARIABLE), what);
    check.status(H5Tset_cset(type.get(), H5T_CSET_UTF8), what);
    const Handle a = check.handle(
        H5Acreate2(object, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose, what);
    const char* text = s.c_str();
    check.status(H5Awrite(a.get(), type.get(), static_cast<const void*>(&text)), what);
  }
}

void check_file_name(const std::string& context, const std::filesystem::path& path) {
  if (path.filename().empty() || path.extension() == ".xmf" || path.extension() == ".tmp") {
    throw std::invalid_argument(context + ": expected a file name such as 'state.h5'");
  }
}

/// Every field has a valid name and `rows` x components values (`rows` the nodes, or a rank's rows).
void validate_fields(const std::string& context, const FieldViews& fields, std::size_t rows, const char* what) {
  const auto bad = [&](const std::string& message) { throw std::invalid_argument(context + ": " + message); };
  for (const auto& [name, field] : fields) {
    if (name.empty() || name == "." || name.find('/') != std::string::npos) {
      bad("field name '" + name + "' is empty, '.' or contains '/'");
    }
    if (field.components < 1) bad("field '" + name + "' has " + std::to_string(field.components) + " components");
    const std::size_t expected = rows * static_cast<std::size_t>(field.components);
    if (field.values.size() != expected) {
      bad("field '" + name + "' has " + std::to_string(field.values.size()) + " values, expected " +
          std::to_string(expected) + " (" + std::to_string(rows) + " " + what + " x " + std::to_string(field.components) +
          " components)");
    }
  }
}

void validate(const std::string& context, const NodeSet& nodes, const BackgroundCells& cells,
              const FieldViews& fields, const OutputAttributes& attributes) {
  const auto bad = [&](const std::string& what) { throw std::invalid_argument(context + ": " + what); };
  if (nodes.dim < 1 || nodes.dim > 3) bad("node dimension must be 1, 2 or 3, got " + std::to_string(nodes.dim));
  const std::size_t n = nodes.size();
  if (n == 0) bad("the node set is empty");
  if (n > static_cast<std::size_t>(std::numeric_limits<int>::max())) bad("too many nodes for int32 cell indices");
  const int per_cell = nodes.dim + 1;
  if (!cells.connectivity.empty()) {
    if (cells.dim != nodes.dim) {
      bad("cells of dimension " + std::to_string(cells.dim) + " over nodes of dimension " + std::to_string(nodes.dim));
    }
    if (cells.vertices_per_cell != per_cell) {
      bad(std::to_string(cells.vertices_per_cell) + " vertices per cell, expected " + std::to_string(per_cell));
    }
    if (cells.connectivity.size() % static_cast<std::size_t>(per_cell) != 0) {
      bad("connectivity length " + std::to_string(cells.connectivity.size()) + " is not a multiple of " +
          std::to_string(per_cell));
    }
    const auto [lo, hi] = std::minmax_element(cells.connectivity.begin(), cells.connectivity.end());
    if (*lo < 0 || static_cast<std::size_t>(*hi) >= n) {
      bad("cell node index " + std::to_string(*lo < 0 ? *lo : *hi) + " outside [0, " + std::to_string(n) + ")");
    }
  }
  validate_fields(context, fields, n, "nodes");
  for (const auto& entry : attributes) {
    if (entry.first.empty()) bad("an attribute has an empty name");
  }
}

void write_hdf5_file(const Checker& check, const std::filesystem::path& file, const NodeSet& nodes,
                     const BackgroundCells& cells, const FieldViews& fields, const OutputAttributes& attributes) {
  Handle h5 = check.handle(H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose,
                           "cannot create '" + file.string() + "'");
  {
    const auto n = static_cast<hsize_t>(nodes.size());
    const auto d = static_cast<hsize_t>(nodes.dim);
    const auto per_cell = d + 1;
    const auto m = static_cast<hsize_t>(cells.connectivity.size()) / per_cell;
    write_dataset(check, h5.get(), "nodes", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {n, d}, nodes.coords.data());
    write_dataset(check, h5.get(), "cells", H5T_STD_I32LE, H5T_NATIVE_INT, {m, per_cell},
                  cells.connectivity.data());
    const Handle group = check.handle(H5Gcreate2(h5.get(), "fields", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                                      H5Gclose, "cannot create group /fields");
    write_attribute(check, group.get(), "format", std::string(kFormatName));
    write_attribute(check, group.get(), "version", kFormatVersion);
    for (const auto& [name, field] : fields) {
      std::vector<hsize_t> dims{n};
      if (field.components > 1) dims.push_back(static_cast<hsize_t>(field.components));
      write_dataset(check, group.get(), name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, dims, field.values.data());
    }
    for (const auto& [name, value] : attributes) write_attribute(check, h5.get(), name, value);
  }
  check.status(H5Fflush(h5.get(), H5F_SCOPE_GLOBAL), "cannot flush '" + file.string() + "'");
  check.status(h5.close(), "cannot close '" + file.string() + "'");
}

// ---- writing collectively ------------------------------------------------------------------------

/// A dataset written through MPI-IO by every rank at once: rank r writes `count` elements from `data`
/// at the file positions `coordinates` (count x rank of the dataset), or everything (`all`), or nothing.
struct Selection {
  bool all = false;
  hsize_t count = 0;
  std::vector<hsize_t> coordinates;
};

void write_dataset_collective(const Checker& check, hid_t parent, const std::string& name, hid_t file_type, hid_t mem_type,
                              const std::vector<hsize_t>& dims, const Selection& mine, const void* data, hid_t transfer) {
  const Handle file_space = check.handle(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr), H5Sclose,
                                         "cannot create the dataspace of " + name);
  const Handle set = check.handle(H5Dcreate2(parent, name.c_str(), file_type, file_space.get(), H5P_DEFAULT, H5P_DEFAULT,
                                             H5P_DEFAULT),
                                  H5Dclose, "cannot create dataset " + name);
  hsize_t total = 1;
  for (const hsize_t d : dims) total *= d;
  if (total == 0) return;
  const hsize_t count = mine.all ? total : mine.count;
  const hsize_t memory_dims = std::max<hsize_t>(count, 1);
  const Handle memory_space = check.handle(H5Screate_simple(1, &memory_dims, nullptr), H5Sclose, "cannot create a memory dataspace");
  if (mine.all) {
    check.status(H5Sselect_all(file_space.get()), "cannot select " + name);
  } else if (count > 0) {
    check.status(H5Sselect_elements(file_space.get(), H5S_SELECT_SET, count, mine.coordinates.data()), "cannot select rows of " + name);
  } else {
    check.status(H5Sselect_none(file_space.get()), "cannot select " + name);
    check.status(H5Sselect_none(memory_space.get()), "cannot select " + name);
  }
  check.status(H5Dwrite(set.get(), mem_type, memory_space.get(), file_space.get(), transfer, count > 0 ? data : nullptr),
               "cannot write dataset " + name);
}

void write_hdf5_file_collective(const Checker& check, MPI_Comm comm, const std::filesystem::path& file, const NodeSet& nodes,
                                const BackgroundCells& cells, const DistributedFields& local, const OutputAttributes& attributes) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  const Handle access = check.handle(H5Pcreate(H5P_FILE_ACCESS), H5Pclose, "cannot create file access properties");
  check.status(H5Pset_fapl_mpio(access.get(), comm, MPI_INFO_NULL), "cannot open the file through MPI-IO");
  Handle h5 = check.handle(H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, access.get()), H5Fclose,
                           "cannot create '" + file.string() + "'");
  const Handle transfer = check.handle(H5Pcreate(H5P_DATASET_XFER), H5Pclose, "cannot create transfer properties");
  check.status(H5Pset_dxpl_mpio(transfer.get(), H5FD_MPIO_COLLECTIVE), "cannot ask for collective transfers");
  {
    const auto n = static_cast<hsize_t>(nodes.size());
    const auto d = static_cast<hsize_t>(nodes.dim);
    const auto per_cell = d + 1;
    const auto m = static_cast<hsize_t>(cells.connectivity.size()) / per_cell;
    const Selection everything_on_rank0{rank == 0, 0, {}};
    write_dataset_collective(check, h5.get(), "nodes", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {n, d}, everything_on_rank0,
                             nodes.coords.data(), transfer.get());
    write_dataset_collective(check, h5.get(), "cells", H5T_STD_I32LE, H5T_NATIVE_INT, {m, per_cell}, everything_on_rank0,
                             cells.connectivity.data(), transfer.get());
    const Handle group = check.handle(H5Gcreate2(h5.get(), "fields", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose,
                                      "cannot create group /fields");
    write_attribute(check, group.get(), "format", std::string(kFormatName));
    write_attribute(check, group.get(), "version", kFormatVersion);
    for (const auto& [name, field] : local.fields) {
      const auto components = static_cast<hsize_t>(field.components);
      std::vector<hsize_t> dims{n};
      if (components > 1) dims.push_back(components);
      Selection mine;
      mine.count = static_cast<hsize_t>(local.rows.size()) * components;
      mine.coordinates.reserve(static_cast<std::size_t>(mine.count) * dims.size());
      for (const int row : local.rows)
        for (hsize_t c = 0; c < components; ++c) {
          mine.coordinates.push_back(static_cast<hsize_t>(row));
          if (components > 1) mine.coordinates.push_back(c);
        }
      write_dataset_collective(check, group.get(), name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, dims, mine, field.values.data(),
                               transfer.get());
    }
    for (const auto& [name, value] : attributes) write_attribute(check, h5.get(), name, value);
  }
  check.status(H5Fflush(h5.get(), H5F_SCOPE_GLOBAL), "cannot flush '" + file.string() + "'");
  check.status(h5.close(), "cannot close '" + file.string() + "'");
}

// ---- reading -------------------------------------------------------------------------------------

struct DatasetShape {
  std::vector<hsize_t> dims;
};

DatasetShape shape_of(const Checker& check, hid_t set, const std::string& name) {
  const Handle space = check.handle(H5Dget_space(set), H5Sclose, "cannot read the dataspace of " + name);
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 0) check.fail("cannot read the rank of " + name);
  DatasetShape shape;
  shape.dims.resize(static_cast<std::size_t>(rank));
  if (rank > 0 && H5Sget_simple_extent_dims(space.get(), shape.dims.data(), nullptr) < 0) {
    check.fail("cannot read the dimensions of " + name);
  }
  return shape;
}

bool link_exists(hid_t location, const char* name) {
  const htri_t e = H5Lexists(location, name, H5P_DEFAULT);
  return e > 0;
}

Handle open_dataset(const Checker& check, hid_t location, const std::string& name, const std::string& shown) {
  if (!link_exists(location, name.c_str())) throw std::runtime_error(check.context + ": missing dataset " + shown);
  return check.handle(H5Dopen2(location, name.c_str(), H5P_DEFAULT), H5Dclose, "cannot open dataset " + shown);
}

OutputAttribute read_attribute(const Checker& check, hid_t object, const std::string& name) {
  const std::string what = "cannot read attribute '" + name + "'";
  const Handle a = check.handle(H5Aopen(object, name.c_str(), H5P_DEFAULT), H5Aclose, what);
  const Handle type = check.handle(H5Aget_type(a.get()), H5Tclose, what);
  const Handle space = check.handle(H5Aget_space(a.get()), H5Sclose, what);
  const hssize_t count = H5Sget_simple_extent_npoints(space.get());
  if (count != 1) throw std::runtime_error(check.context + ": attribute '" + name + "' is not a scalar");
  switch (H5Tget_class(type.get())) {
    case H5T_FLOAT: {
      double v = 0;
      check.status(H5Aread(a.get(), H5T_NATIVE_DOUBLE, &v), what);
      return v;
    }
    case H5T_INTEGER: {
      std::int64_t v = 0;
      check.status(H5Aread(a.get(), H5T_NATIVE_INT64, &v), what);
      return v;
    }
    case H5T_STRING: {
      if (H5Tis_variable_str(type.get()) > 0) {
        const Handle mem = check.handle(H5Tcopy(H5T_C_S1), H5Tclose, what);
        check.status(H5Tset_size(mem.get(), H5T_VARIABLE), what);
        check.status(H5Tset_cset(mem.get(), H5Tget_cset(type.get())), what);
        char* text = nullptr;
        check.status(H5Aread(a.get(), mem.get(), static_cast<void*>(&text)), what);
        std::string s = text != nullptr ? text : "";
        H5free_memory(text);
        return s;
      }
      const std::size_t size = H5Tget_size(type.get());
      std::string s(size, '\0');
      check.status(H5Aread(a.get(), type.get(), s.data()), what);
      s.resize(std::strlen(s.c_str()));
      return s;
    }
    default:
      throw std::runtime_error(check.context + ": attribute '" + name + "' is neither a number nor a string");
  }
}

herr_t collect_name(hid_t, const char* name, const H5A_info_t*, void* data) {
  static_cast<std::vector<std::string>*>(data)->emplace_back(name);
  return 0;
}

/// Moves a written temporary .h5 into place with its XDMF sidecar (2D and 3D): fsync, the sidecar
/// renamed first and the data last, so that whenever the new .h5 is in place its .xmf is too.
/// On failure nothing new is left behind.
void place_files(const std::string& context, const std::filesystem::path& path, const std::filesystem::path& h5_tmp,
                 const NodeSet& nodes, const BackgroundCells& cells, const FieldViews& fields) {
  const auto xmf = xdmf_sidecar_path(path);
  const auto xmf_tmp = io_detail::temporary_path(xmf);
  bool xmf_renamed = false;
  try {
    io_detail::sync_file(h5_tmp, context);
    if (nodes.dim >= 2) {
      std::vector<std::pair<std::string, int>> listed;
      for (const auto& [name, field] : fields) listed.emplace_back(name, field.components);
      const std::string xml = io_detail::xdmf_document(path.filename().string(), nodes.dim, nodes.size(),
                                                       cells.connectivity.size() / static_cast<std::size_t>(nodes.dim + 1),
                                                       listed);
      io_detail::write_and_sync(xmf_tmp, xml, context);
      io_detail::rename_into_place(xmf_tmp, xmf, context);
      xmf_renamed = true;
    }
    io_detail::rename_into_place(h5_tmp, path, context);
  } catch (...) {
    io_detail::remove_quietly(h5_tmp);
    io_detail::remove_quietly(xmf_tmp);
    if (xmf_renamed) io_detail::remove_quietly(xmf);  // it would describe an .h5 that is not there
    throw;
  }
  io_detail::sync_parent_directory(path);
}

}  // namespace

std::filesystem::path xdmf_sidecar_path(const std::filesystem::path& h5_path) {
  std::filesystem::path xmf = h5_path;
  xmf.replace_extension(".xmf");
  return xmf;
}

void write_field_hdf5(const std::filesystem::path& path, const NodeSet& nodes, const BackgroundCells& cells,
                      const FieldViews& fields, const OutputAttributes& attributes) {
  const std::string context = "write_field_hdf5: " + path.string();
  check_file_name(context, path);
  validate(context, nodes, cells, fields, attributes);

  const auto h5_tmp = io_detail::temporary_path(path);
  const QuietHdf5Errors quiet;
  try {
    write_hdf5_file(Checker{context}, h5_tmp, nodes, cells, fields, attributes);
  } catch (...) {
    io_detail::remove_quietly(h5_tmp);
    throw;
  }
  place_files(context, path, h5_tmp, nodes, cells, fields);
}

void write_field_hdf5(MPI_Comm comm, const std::filesystem::path& path, const NodeSet& nodes, const BackgroundCells& cells,
                      const DistributedFields& local, const OutputAttributes& attributes) {
  const std::string context = "write_field_hdf5: " + path.string();
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  // Every rank checks its own part; all learn whether any failed, so that none enters the
  // collective writes alone.
  std::string refusal;
  try {
    check_file_name(context, path);
    validate(context, nodes, cells, {}, attributes);
    validate_fields(context, local.fields, local.rows.size(), "rows of this rank");
    for (const int row : local.rows)
      if (row < 0 || static_cast<std::size_t>(row) >= nodes.size())
        throw std::invalid_argument(context + ": row " + std::to_string(row) + " outside [0, " + std::to_string(nodes.size()) + ")");
  } catch (const std::invalid_argument& e) {
    refusal = e.what();
  }
  long long rows = static_cast<long long>(local.rows.size()), all_rows = 0;
  int refused = refusal.empty() ? 0 : 1, any_refused = 0;
  MPI_Allreduce(&rows, &all_rows, 1, MPI_LONG_LONG, MPI_SUM, comm);
  MPI_Allreduce(&refused, &any_refused, 1, MPI_INT, MPI_MAX, comm);
  if (any_refused != 0) throw std::invalid_argument(refused != 0 ? refusal : context + ": another rank's part is inconsistent");
  if (all_rows != static_cast<long long>(nodes.size()))
    throw std::invalid_argument(context + ": the ranks hold " + std::to_string(all_rows) + " rows together, the file has " +
                                std::to_string(nodes.size()) + " nodes");

  // One temporary name for all ranks: rank 0's.
  std::string h5_tmp = rank == 0 ? io_detail::temporary_path(path).string() : std::string();
  auto length = static_cast<int>(h5_tmp.size());
  MPI_Bcast(&length, 1, MPI_INT, 0, comm);
  h5_tmp.resize(static_cast<std::size_t>(length));
  MPI_Bcast(h5_tmp.data(), length, MPI_CHAR, 0, comm);

  const QuietHdf5Errors quiet;
  std::string failure;
  try {
    write_hdf5_file_collective(Checker{context}, comm, h5_tmp, nodes, cells, local, attributes);
  } catch (const std::exception& e) {
    failure = e.what();
  }
  int failed = failure.empty() ? 0 : 1, any_failed = 0;
  MPI_Allreduce(&failed, &any_failed, 1, MPI_INT, MPI_MAX, comm);
  if (any_failed == 0 && rank == 0) {
    try {
      place_files(context, path, h5_tmp, nodes, cells, local.fields);
    } catch (const std::exception& e) {
      failed = 1;
      failure = e.what();
    }
  }
  if (any_failed != 0 && rank == 0) io_detail::remove_quietly(h5_tmp);
  MPI_Allreduce(MPI_IN_PLACE, &failed, 1, MPI_INT, MPI_MAX, comm);
  if (failed != 0 || any_failed != 0)
    throw std::runtime_error(!failure.empty() ? failure : context + ": the file could not be written (the message is on rank 0)");
}

ReplicatedShare::ReplicatedShare(MPI_Comm comm, std::size_t nodes, const FieldViews& whole) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const std::size_t begin = nodes * static_cast<std::size_t>(rank) / static_cast<std::size_t>(size);
  const std::size_t end = nodes * static_cast<std::size_t>(rank + 1) / static_cast<std::size_t>(size);
  rows_.resize(end - begin);
  for (std::size_t i = 0; i < rows_.size(); ++i) rows_[i] = static_cast<int>(begin + i);
  for (const auto& [name, view] : whole) {
    const auto components = static_cast<std::size_t>(std::max(view.components, 1));
    if (view.values.size() != nodes * components)
      throw std::invalid_argument("ReplicatedShare: field '" + name + "' has " + std::to_string(view.values.size()) + " values, expected " +
                                  std::to_string(nodes) + " x " + std::to_string(components));
    fields_.emplace(name, FieldView{view.values.subspan(begin * components, (end - begin) * components), view.components});
  }
}

namespace {

/// Reads whole datasets of N rows: all at once on one rank; on several, each rank reads a
/// contiguous block of the rows through MPI-IO (collective transfers) and the blocks are gathered,
/// so that every rank holds the dataset and none read it whole.
class RowReader {
 public:
  RowReader(const Checker& check, MPI_Comm comm)
      : check_(check), comm_(comm), size_(size_of(comm)), transfer_(collective_transfer(check, size_)) {
    if (size_ > 1) MPI_Comm_rank(comm, &rank_);
    ranks_here_ = ranks_on_this_machine(comm);
    // The smallest share of any rank, so that all ranks refuse a dataset or none.
    double share = static_cast<double>(available_memory_bytes()) / ranks_here_;
    if (size_ > 1) MPI_Allreduce(MPI_IN_PLACE, &share, 1, MPI_DOUBLE, MPI_MIN, comm);
    available_ = share;
  }

  /// The file access: MPI-IO on several ranks, with the metadata read by one rank for all.
  Handle access() const {
    Handle a = check_.handle(H5Pcreate(H5P_FILE_ACCESS), H5Pclose, "cannot create file access properties");
    if (size_ > 1) {
      check_.status(H5Pset_fapl_mpio(a.get(), comm_, MPI_INFO_NULL), "cannot open the file through MPI-IO");
      check_.status(H5Pset_all_coll_metadata_ops(a.get(), true), "cannot ask for collective metadata reads");
    }
    return a;
  }

  /// Reads `set` (dims[0] rows, the product of the other dims per row) whole. A dataset larger
  /// than the memory this machine can still give each of its ranks is refused before anything is
  /// allocated (every rank receives it whole).
  template <class T>
  [[nodiscard]] std::vector<T> read(hid_t set, hid_t mem_type, const std::vector<hsize_t>& dims, const std::string& shown) const {
    long double values = 1;
    for (const hsize_t d : dims) values *= static_cast<long double>(d);
    const long double bytes = values * sizeof(T);
    if (available_ > 0 && bytes > available_)
      throw std::runtime_error(fmt::format("{}: {} holds {:.3g} GiB, more than the {:.3g} GiB {}: every rank holds a file's nodes and "
                                           "fields whole; use a machine with more memory per rank, or fewer ranks per machine",
                                           check_.context, shown, static_cast<double>(bytes / 1073741824.0L),
                                           static_cast<double>(available_ / 1073741824.0L),
                                           ranks_here_ == 1 ? std::string("this machine has free")
                                                            : fmt::format("free for each of the {} ranks on this machine", ranks_here_)));
    if (size_ > 1 && values > static_cast<long double>(std::numeric_limits<int>::max()))
      throw std::runtime_error(fmt::format("{}: {} holds more than 2^31 values, more than one gather can take", check_.context, shown));
    std::vector<T> out(static_cast<std::size_t>(values));
    if (out.empty()) return out;
    if (size_ == 1) {
      check_.status(H5Dread(set, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()), "cannot read " + shown);
      return out;
    }
    const hsize_t rows = dims[0];
    const std::size_t row_size = out.size() / static_cast<std::size_t>(rows);
    auto first_row = [&](int r) { return rows * static_cast<hsize_t>(r) / static_cast<hsize_t>(size_); };
    const hsize_t begin = first_row(rank_), count = first_row(rank_ + 1) - begin;
    const Handle file_space = check_.handle(H5Dget_space(set), H5Sclose, "cannot read the dataspace of " + shown);
    const hsize_t memory_dims = std::max<hsize_t>(count * row_size, 1);
    const Handle memory_space = check_.handle(H5Screate_simple(1, &memory_dims, nullptr), H5Sclose, "cannot create a memory dataspace");
    if (count > 0) {
      std::vector<hsize_t> start(dims.size(), 0), block(dims);
      start[0] = begin;
      block[0] = count;
      check_.status(H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start.data(), nullptr, block.data(), nullptr),
                    "cannot select rows of " + shown);
    } else {
      check_.status(H5Sselect_none(file_space.get()), "cannot select " + shown);
      check_.status(H5Sselect_none(memory_space.get()), "cannot select " + shown);
    }
    std::vector<T> mine(static_cast<std::size_t>(count) * row_size);
    check_.status(H5Dread(set, mem_type, memory_space.get(), file_space.get(), transfer_.get(), mine.empty() ? nullptr : mine.data()),
                  "cannot read " + shown);
    std::vector<int> counts(static_cast<std::size_t>(size_)), displacements(static_cast<std::size_t>(size_));
    for (int r = 0; r < size_; ++r) {
      displacements[std::size_t(r)] = static_cast<int>(first_row(r) * row_size);
      counts[std::size_t(r)] = static_cast<int>((first_row(r + 1) - first_row(r)) * row_size);
    }
    const MPI_Datatype type = std::is_same_v<T, double> ? MPI_DOUBLE : MPI_INT;
    MPI_Allgatherv(mine.data(), static_cast<int>(mine.size()), type, out.data(), counts.data(), displacements.data(), type, comm_);
    return out;
  }

 private:
  static int size_of(MPI_Comm comm) {
    int initialized = 0, size = 1;
    MPI_Initialized(&initialized);  // the serial form serves programs without MPI too
    if (initialized != 0) MPI_Comm_size(comm, &size);
    return size;
  }
  static Handle collective_transfer(const Checker& check, int size) {
    if (size == 1) return {};
    Handle transfer = check.handle(H5Pcreate(H5P_DATASET_XFER), H5Pclose, "cannot create transfer properties");
    check.status(H5Pset_dxpl_mpio(transfer.get(), H5FD_MPIO_COLLECTIVE), "cannot ask for collective transfers");
    return transfer;
  }

  /// The ranks of comm that share this machine's memory (1 without MPI).
  static int ranks_on_this_machine(MPI_Comm comm) {
    int initialized = 0;
    MPI_Initialized(&initialized);
    if (initialized == 0) return 1;
    MPI_Comm here = MPI_COMM_NULL;
    MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &here);
    int n = 1;
    MPI_Comm_size(here, &n);
    MPI_Comm_free(&here);
    return n;
  }

  const Checker& check_;
  MPI_Comm comm_;
  int size_ = 1, rank_ = 0;
  Handle transfer_;
  int ranks_here_ = 1;
  long double available_ = 0;  ///< bytes per rank of this machine; 0: unknown (no limit)
};

FieldFile read_field_file(const std::filesystem::path& path, MPI_Comm comm, const FieldFileSelection& selection) {
  const std::string context = "read_field_hdf5: " + path.string();
  const QuietHdf5Errors quiet;
  const Checker check{context};
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw std::runtime_error(context + ": no such file");
  const htri_t is_hdf5 = H5Fis_hdf5(path.c_str());
  if (is_hdf5 <= 0) throw std::runtime_error(context + ": not an HDF5 file");
  const RowReader reader(check, comm);
  const Handle access = reader.access();
  const Handle h5 = check.handle(H5Fopen(path.c_str(), H5F_ACC_RDONLY, access.get()), H5Fclose, "cannot open");

  FieldFile out;
  // /nodes: N x d
  std::size_t n = 0;
  {
    const Handle set = open_dataset(check, h5.get(), "nodes", "/nodes");
    const auto dims = shape_of(check, set.get(), "/nodes").dims;
    if (dims.size() != 2 || dims[1] < 1 || dims[1] > 3) {
      throw std::runtime_error(context + ": /nodes must be N x d with d in 1..3");
    }
    n = static_cast<std::size_t>(dims[0]);
    const int d = static_cast<int>(dims[1]);
    out.nodes = NodeSet(d, reader.read<double>(set.get(), H5T_NATIVE_DOUBLE, dims, "/nodes"));
  }
  // /cells: M x (d+1)
  if (selection.cells) {
    const int d = out.nodes.dim;
    const Handle set = open_dataset(check, h5.get(), "cells", "/cells");
    const auto dims = shape_of(check, set.get(), "/cells").dims;
    if (dims.size() != 2 || dims[1] != static_cast<hsize_t>(d + 1)) {
      throw std::runtime_error(context + ": /cells must be M x " + std::to_string(d + 1));
    }
    out.cells.dim = d;
    out.cells.vertices_per_cell = d + 1;
    out.cells.connectivity = reader.read<int>(set.get(), H5T_NATIVE_INT, dims, "/cells");
    for (const int v : out.cells.connectivity) {
      if (v < 0 || static_cast<std::size_t>(v) >= n) {
        throw std::runtime_error(context + ": /cells refers to node " + std::to_string(v) + " of " + std::to_string(n));
      }
    }
    const std::size_t m = static_cast<std::size_t>(dims[0]);
    out.cells.measures.resize(m);
    for (std::size_t c = 0; c < m; ++c) out.cells.measures[c] = simplex_signed_measure(out.nodes, out.cells.cell(c));
  }
  // /fields/<name>
  if (!selection.fields || !selection.fields->empty()) {
    if (!link_exists(h5.get(), "fields")) throw std::runtime_error(context + ": missing group /fields");
    const Handle group = check.handle(H5Gopen2(h5.get(), "fields", H5P_DEFAULT), H5Gclose, "cannot open /fields");
    std::vector<std::string> names;
    if (selection.fields) {
      names = *selection.fields;
    } else {
      H5G_info_t info{};
      check.status(H5Gget_info(group.get(), &info), "cannot list /fields");
      for (hsize_t i = 0; i < info.nlinks; ++i) {
        const ssize_t length = H5Lget_name_by_idx(group.get(), ".", H5_INDEX_NAME, H5_ITER_INC, i, nullptr, 0, H5P_DEFAULT);
        if (length < 0) check.fail("cannot list /fields");
        std::string name(static_cast<std::size_t>(length) + 1, '\0');
        if (H5Lget_name_by_idx(group.get(), ".", H5_INDEX_NAME, H5_ITER_INC, i, name.data(), name.size(), H5P_DEFAULT) < 0) {
          check.fail("cannot list /fields");
        }
        name.resize(static_cast<std::size_t>(length));
        names.push_back(std::move(name));
      }
    }
    for (std::string& name : names) {
      const std::string shown = "/fields/" + name;
      const Handle set = open_dataset(check, group.get(), name, shown);
      const auto dims = shape_of(check, set.get(), shown).dims;
      if (dims.empty() || dims.size() > 2 || dims[0] != n) {
        throw std::runtime_error(context + ": " + shown + " must have " + std::to_string(n) +
                                 " rows (one per node), with at most one more dimension");
      }
      FieldData field;
      field.components = dims.size() == 2 ? static_cast<int>(dims[1]) : 1;
      field.values = reader.read<double>(set.get(), H5T_NATIVE_DOUBLE, dims, shown);
      out.fields.emplace(std::move(name), std::move(field));
    }
  }
  // Root attributes.
  if (selection.attributes) {
    std::vector<std::string> names;
    hsize_t index = 0;
    check.status(H5Aiterate2(h5.get(), H5_INDEX_NAME, H5_ITER_INC, &index, collect_name, &names),
                 "cannot list the root attributes");
    for (const auto& name : names) out.attributes.emplace(name, read_attribute(check, h5.get(), name));
  }
  return out;
}

}  // namespace

FieldFile read_field_hdf5(const std::filesystem::path& path) { return read_field_file(path, MPI_COMM_SELF, {}); }

FieldFile read_field_hdf5(const std::filesystem::path& path, MPI_Comm comm, const FieldFileSelection& selection) {
  return read_field_file(path, comm, selection);
}

}  // namespace lmeform
