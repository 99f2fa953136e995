// Internal helpers of lmeform_io: atomic files (temporary paths, fsync, rename, cleanup) and XDMF text.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace lmeform::io_detail {

/// "<path>.<pid>.<n>.tmp": unique per process and call
[[nodiscard]] std::filesystem::path temporary_path(const std::filesystem::path& path);

/// Writes `content` to `file` (created or truncated), flushes and fsyncs it. Throws
/// std::runtime_error "<context>: cannot write <file>: <OS error>".
void write_and_sync(const std::filesystem::path& file, std::string_view content, std::string_view context);

/// fsyncs an existing file (after HDF5 closed it). Throws like write_and_sync.
void sync_file(const std::filesystem::path& file, std::string_view context);

/// Renames from onto to (atomic within a file system). Throws
/// "<context>: cannot rename <from> to <to>: <OS error>".
void rename_into_place(const std::filesystem::path& from, const std::filesystem::path& to, std::string_view context);

/// Best-effort fsync of the folder holding `file`, so that a rename survives a crash.
void sync_parent_directory(const std::filesystem::path& file) noexcept;

/// Removes a file if it exists; never throws.
void remove_quietly(const std::filesystem::path& file) noexcept;

/// The XDMF 3 document for a file written by write_field_hdf5 (dim 2 or 3). `fields` lists
/// (name, components) in file order; `h5_file_name` is the .h5 name relative to the .xmf.
[[nodiscard]] std::string xdmf_document(std::string_view h5_file_name, int dim, std::size_t nodes, std::size_t cells,
                                        const std::vector<std::pair<std::string, int>>& fields);

struct XdmfStep {
  double time = 0;
  std::string h5_file;  ///< relative to the .xmf
  int dim = 2;
  std::size_t nodes = 0, cells = 0;
  std::vector<std::pair<std::string, int>> fields;
};

/// An XDMF 3 temporal collection of write_field_hdf5 files (ParaView plays it as an animation).
[[nodiscard]] std::string xdmf_time_series_document(const std::vector<XdmfStep>& steps);

}  // namespace lmeform::io_detail
