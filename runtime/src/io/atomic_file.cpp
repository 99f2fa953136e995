// Atomic file writing: "<path>.<pid>.<n>.tmp", fsync, rename. POSIX calls so that every OS error is reported.
#include "io_detail.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <string>
#include <stdexcept>
#include <system_error>

#include "lmeform/output.hpp"

namespace lmeform::io_detail {
namespace {

[[noreturn]] void throw_os_error(std::string_view context, std::string_view action, const std::filesystem::path& file,
                                 int error) {
  throw std::runtime_error(std::string(context) + ": cannot " + std::string(action) + " '" + file.string() +
                           "': " + std::system_category().message(error));
}

// Closes a descriptor on scope exit unless released.
class Descriptor {
 public:
  explicit Descriptor(int fd) noexcept : fd_(fd) {}
  Descriptor(const Descriptor&) = delete;
  Descriptor& operator=(const Descriptor&) = delete;
  ~Descriptor() {
    if (fd_ >= 0) ::close(fd_);
  }
  [[nodiscard]] int get() const noexcept { return fd_; }
  int release() noexcept {
    const int fd = fd_;
    fd_ = -1;
    return fd;
  }

 private:
  int fd_;
};

}  // namespace

std::filesystem::path temporary_path(const std::filesystem::path& path) {
  // Unique per process and call: two runs that write the same file (two ranks or two tests filling
  // one JIT cache) must not rename each other's half-written temporary away.
  static std::atomic<unsigned long> counter{0};
  std::filesystem::path tmp = path;
  tmp += "." + std::to_string(::getpid()) + "." + std::to_string(counter.fetch_add(1)) + ".tmp";
  return tmp;
}

void write_and_sync(const std::filesystem::path& file, std::string_view content, std::string_view context) {
  Descriptor fd(::open(file.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666));
  if (fd.get() < 0) throw_os_error(context, "create", file, errno);
  const char* data = content.data();
  std::size_t left = content.size();
  while (left > 0) {
    const ssize_t n = ::write(fd.get(), data, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw_os_error(context, "write", file, errno);
    }
    data += n;
    left -= static_cast<std::size_t>(n);
  }
  if (::fsync(fd.get()) != 0) throw_os_error(context, "sync", file, errno);
  if (::close(fd.release()) != 0) throw_os_error(context, "close", file, errno);
}

void sync_file(const std::filesystem::path& file, std::string_view context) {
  Descriptor fd(::open(file.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.get() < 0) throw_os_error(context, "open", file, errno);
  if (::fsync(fd.get()) != 0) throw_os_error(context, "sync", file, errno);
}

void rename_into_place(const std::filesystem::path& from, const std::filesystem::path& to, std::string_view context) {
  if (::rename(from.c_str(), to.c_str()) != 0) {
    const int error = errno;
    throw std::runtime_error(std::string(context) + ": cannot rename '" + from.string() + "' to '" + to.string() +
                             "': " + std::system_category().message(error));
  }
}

void sync_parent_directory(const std::filesystem::path& file) noexcept {
  std::filesystem::path dir = file.parent_path();
  if (dir.empty()) dir = ".";
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  (void)::fsync(fd);
  ::close(fd);
}

void remove_quietly(const std::filesystem::path& file) noexcept {
  std::error_code ec;
  // Only plain files and links: a folder that happens to have the name is not ours to remove.
  const auto status = std::filesystem::symlink_status(file, ec);
  if (ec || status.type() == std::filesystem::file_type::directory) return;
  std::filesystem::remove(file, ec);
}

}  // namespace lmeform::io_detail

namespace lmeform {

void write_text_atomically(const std::filesystem::path& path, std::string_view content) {
  const std::string context = "write_text_atomically: " + path.string();
  const auto tmp = io_detail::temporary_path(path);
  try {
    io_detail::write_and_sync(tmp, content, context);
    io_detail::rename_into_place(tmp, path, context);
  } catch (...) {
    io_detail::remove_quietly(tmp);
    throw;
  }
  io_detail::sync_parent_directory(path);
}

}  // namespace lmeform
