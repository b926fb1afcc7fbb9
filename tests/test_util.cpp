#include "tests/test_util.h"

#include <fstream>
#include <iterator>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <random>
#include <stdexcept>
#include <sys/wait.h>
#include <unistd.h>

namespace gimlod::test {

std::filesystem::path sharedData() { return GIMLOD_SHARED_DATA; }
bool haveSharedData() { return std::filesystem::exists(sharedData() / "terrain"); }
std::filesystem::path repoData() { return GIMLOD_REPO_DATA; }

std::filesystem::path realData(const std::string& relative) {
  const std::filesystem::path shipped = repoData() / relative;
  return std::filesystem::exists(shipped) ? shipped : sharedData() / relative;
}

bool haveRealData(const std::string& relative) { return std::filesystem::exists(realData(relative)); }

bool sharedDataRequired() {
  for (const char* name : {"CI", "GIMLOD_REQUIRE_SHARED_DATA"}) {
    const char* v = std::getenv(name);
    if (v && *v && std::string(v) != "0" && std::string(v) != "false") return true;
  }
  return false;
}
std::filesystem::path appPath() {
#ifdef GIMLOD_APP
  return GIMLOD_APP;
#else
  throw std::logic_error("this build has no gimlod program (GIMLOD_RUNTIME_ONLY)");
#endif
}

TempDir::TempDir(const std::string& tag) {
  std::random_device rd;
  path_ = std::filesystem::temp_directory_path() /
          (tag + "-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

std::string fileBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

int runCommand(const std::string& command, std::string* output) {
  std::string cmd = command + " 2>&1";
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return -1;
  std::array<char, 4096> buf{};
  std::string out;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) out.append(buf.data(), n);
  int status = ::pclose(pipe);
  if (output) *output = out;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace gimlod::test
