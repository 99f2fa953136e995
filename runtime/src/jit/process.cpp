#include "lmeform/process.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <random>
#include <stdexcept>

#include <fmt/format.h>

extern char** environ;

namespace lmeform {

namespace fs = std::filesystem;

namespace {

std::string read_and_remove(const fs::path& path) {
  std::string text;
  {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream read;
    read << in.rdbuf();
    text = std::move(read).str();
  }
  std::error_code ec;
  fs::remove(path, ec);
  return text;
}

fs::path temporary_file(const std::string& stem) {
  static thread_local std::mt19937_64 random{std::random_device{}()};
  return fs::temp_directory_path() / fmt::format("{}-{}-{:016x}", stem, ::getpid(), random());
}

}  // namespace

ProcessResult run_process(const std::vector<std::string>& argv) {
  // stdout and stderr go to files (pipes would need a reader for each to avoid a full-pipe stall).
  const fs::path out_path = temporary_file("lmeform-out"), err_path = temporary_file("lmeform-err");
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  posix_spawn_file_actions_addopen(&actions, 2, err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = 0;
  const int status = posix_spawnp(&pid, args[0], &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (status != 0) {
    std::error_code ec;
    fs::remove(out_path, ec);
    fs::remove(err_path, ec);
    throw std::runtime_error(fmt::format("cannot run {}: {}", argv[0], std::strerror(status)));
  }
  int wstatus = 0;
  while (::waitpid(pid, &wstatus, 0) < 0 && errno == EINTR) {
  }
  ProcessResult r;
  r.exit_code = WIFEXITED(wstatus) ? WEXITSTATUS(wstatus) : 128 + (WIFSIGNALED(wstatus) ? WTERMSIG(wstatus) : 0);
  r.out = read_and_remove(out_path);
  r.err = read_and_remove(err_path);
  return r;
}

fs::path executable_directory() {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : self.parent_path();
}

}  // namespace lmeform
