// Output files: nodal fields in HDF5 with an XDMF sidecar (opens in ParaView), and atomic writes
// of small text files. Nothing is ever half-written: every file is written to "<path>.tmp" and
// renamed into place at the end; on any error the temporaries are removed and an exception
// naming the path and the HDF5 / OS error is thrown.
//
// The HDF5 writer comes in two forms: serial (one rank, the data gathered in the original node
// order) and collective (every rank writes the rows it owns into the same file through MPI-IO; the
// file is the same). The reader too: serial, or collective (every rank reads a block of the rows and
// receives the whole). Library `lmeform_io` (alias `lmeform::io`); see docs/output.md for the layout.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include <mpi.h>

#include "lmeform/delaunay.hpp"
#include "lmeform/node_set.hpp"

namespace lmeform {

/// A nodal field to write: `components` values per node, node-major
/// (value k of node a is values[a * components + k]); values.size() == nodes * components.
struct FieldView {
  std::span<const double> values;
  int components = 1;
};

/// A root attribute: a number (energy, eps), an integer (step, iterations) or a string.
/// An `int` argument becomes std::int64_t, a string literal becomes std::string.
using OutputAttribute = std::variant<double, std::int64_t, std::string>;

using FieldViews = std::map<std::string, FieldView, std::less<>>;
using OutputAttributes = std::map<std::string, OutputAttribute, std::less<>>;

/// Writes `path` (HDF5) with
///   /nodes            N x d   float64   (the node coordinates; r, z for axisymmetric runs)
///   /cells            M x (d+1) int32   (background cells, 0-based node indices)
///   /fields/<name>    N or N x components float64
///   root attributes   one per entry of `attributes` (float64, int64 or UTF-8 string)
/// and, for d = 2 or 3, the XDMF 3 sidecar "<stem>.xmf" next to it (Triangle / Tetrahedron
/// topology, XY / XYZ geometry, one node-centred Attribute per field), which references the .h5 by
/// its file name (keep the two files in the same folder). In 1D only the .h5 is written.
/// Both files appear together or not at all (written as "*.tmp", renamed at the end).
/// Throws std::invalid_argument for inconsistent input (field length, cell indices, field names),
/// std::runtime_error naming the path and the HDF5 / OS error when writing fails.
void write_field_hdf5(const std::filesystem::path& path, const NodeSet& nodes, const BackgroundCells& cells,
                      const FieldViews& fields, const OutputAttributes& attributes = {});

/// One rank's part of nodal fields written collectively: the file rows it holds (original node
/// indices) and, per field, its values there (value k of row rows[i] is values[i * components + k]).
/// The ranks' rows together are every node once.
struct DistributedFields {
  std::span<const int> rows;
  FieldViews fields;
};

/// The collective form of write_field_hdf5: call it on every rank of comm with the same path, nodes,
/// cells, field names and attributes (all replicated) and this rank's rows. Rank 0 writes /nodes and
/// /cells, every rank its own rows of each field, all through one MPI-IO file; rank 0 then writes the
/// sidecar and renames both into place. The file equals the serial writer's. Throws on every rank
/// when any rank's input is inconsistent or the file cannot be written (nothing is left behind).
void write_field_hdf5(MPI_Comm comm, const std::filesystem::path& path, const NodeSet& nodes, const BackgroundCells& cells,
                      const DistributedFields& local, const OutputAttributes& attributes = {});

/// A rank's share of fields that every rank of comm holds whole (arrays gathered on all ranks):
/// its contiguous block of the rows [0, nodes) and views of the fields there, for the collective
/// writers. The views point into the whole fields, which must outlive the share.
class ReplicatedShare {
 public:
  ReplicatedShare(MPI_Comm comm, std::size_t nodes, const FieldViews& whole);
  [[nodiscard]] DistributedFields part() const { return {rows_, fields_}; }

 private:
  std::vector<int> rows_;
  FieldViews fields_;
};

/// The XDMF sidecar's path for an HDF5 path: "out/state.h5" -> "out/state.xmf".
[[nodiscard]] std::filesystem::path xdmf_sidecar_path(const std::filesystem::path& h5_path);

/// A field read back from a file.
struct FieldData {
  std::vector<double> values;
  int components = 1;
};

/// Everything write_field_hdf5 stores. cells.measures are recomputed from the coordinates.
struct FieldFile {
  NodeSet nodes;
  BackgroundCells cells;
  std::map<std::string, FieldData, std::less<>> fields;
  std::map<std::string, OutputAttribute, std::less<>> attributes;
};

/// Reads a file written by write_field_hdf5 (for tests and restarts). Throws std::runtime_error
/// naming the path and what is missing or malformed (e.g. "missing dataset /nodes").
[[nodiscard]] FieldFile read_field_hdf5(const std::filesystem::path& path);

/// What a read takes from a field file besides its nodes.
struct FieldFileSelection {
  bool cells = true;
  std::optional<std::vector<std::string>> fields;  ///< these fields (each must exist); none given: all
  bool attributes = true;
};

/// The same, collectively: every rank of comm calls it with the same path and selection, and every
/// rank receives the selected parts whole. The ranks read through MPI-IO, each a contiguous block of
/// every dataset's rows (the metadata read by one for all), and gather the blocks: no rank reads a
/// whole dataset, and what the selection leaves out is not read at all. The errors are those of
/// the serial form, on every rank.
[[nodiscard]] FieldFile read_field_hdf5(const std::filesystem::path& path, MPI_Comm comm, const FieldFileSelection& selection = {});

/// One step of a time series: a file written by write_field_hdf5 and its time.
struct TimeSeriesStep {
  double time = 0;
  std::filesystem::path h5_file;  ///< relative to the folder of the collection file
  int dim = 2;                    ///< 2 or 3
  std::size_t nodes = 0, cells = 0;
  std::vector<std::pair<std::string, int>> fields;  ///< (name, components) as written
};

/// Writes (atomically) an XDMF 3 temporal collection over the steps' HDF5 files: ParaView opens
/// it as one data set with a time slider. The steps' own geometry is used, so moving nodes move.
void write_xdmf_time_series(const std::filesystem::path& path, std::span<const TimeSeriesStep> steps);

/// A time series being written: each step's fields as `series/<name>_<step>.h5` in a folder, and
/// the collection `<name>.xmf` over all steps rewritten after each (a run that stops keeps a
/// readable series).
class TimeSeriesWriter {
 public:
  TimeSeriesWriter(std::filesystem::path directory, std::string name)
      : directory_(std::move(directory)), name_(std::move(name)) {}
  /// Writes one step at `time`.
  void write(double time, int step, const NodeSet& nodes, const BackgroundCells& cells, const FieldViews& fields,
             const OutputAttributes& attributes);
  /// The same, collectively: every rank of comm calls it with its own rows (rank 0 writes the collection).
  void write(MPI_Comm comm, double time, int step, const NodeSet& nodes, const BackgroundCells& cells,
             const DistributedFields& local, const OutputAttributes& attributes);
  /// The file of a step, relative to the folder.
  [[nodiscard]] std::filesystem::path file_of(int step) const;
  /// The steps written so far (a restart puts back those of the run it continues).
  [[nodiscard]] const std::vector<TimeSeriesStep>& steps() const noexcept { return steps_; }
  void restore(std::vector<TimeSeriesStep> steps) { steps_ = std::move(steps); }

 private:
  void add_step(double time, const std::filesystem::path& file, const NodeSet& nodes, const BackgroundCells& cells,
                const FieldViews& fields, bool write_collection);

  std::filesystem::path directory_;
  std::string name_;
  std::vector<TimeSeriesStep> steps_;
};

/// Writes a small text file (JSON, CSV, a table) atomically: "<path>.tmp", flushed and fsynced,
/// then renamed onto `path`. On failure the temporary is removed and std::runtime_error names the
/// path and the OS error; an existing `path` is left as it was.
void write_text_atomically(const std::filesystem::path& path, std::string_view content);

}  // namespace lmeform
