#include "tests/test_util.h"

#include <fstream>
#include <iterator>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <string>
#include <random>
#include <stdexcept>
#include <poll.h>
#include <sys/inotify.h>
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
std::filesystem::path testCache() { return GIMLOD_TEST_CACHE; }

std::string atlasLibraries() {
#ifdef GIMLOD_ATLAS_LIBRARIES
  return GIMLOD_ATLAS_LIBRARIES;
#else
  throw std::logic_error("this build has no atlas libraries (GIMLOD_RUNTIME_ONLY)");
#endif
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
  path_ =
      std::filesystem::temp_directory_path() / (tag + "-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

bool waitForFiles(const std::filesystem::path& dir, const std::function<bool()>& ready,
                  std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  const int fd = ::inotify_init1(IN_CLOEXEC | IN_NONBLOCK);
  if (fd < 0) throw std::runtime_error("inotify_init1: " + std::string(std::strerror(errno)));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  if (::inotify_add_watch(fd, dir.c_str(), IN_CREATE | IN_MODIFY | IN_CLOSE_WRITE | IN_MOVED_TO) < 0)
    throw std::runtime_error("inotify_add_watch " + dir.string() + ": " + std::strerror(errno));
  // Checked after the watch is in place, so a write between the check and the wait is seen.
  while (!ready()) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return false;
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, int(left.count())) < 0 && errno != EINTR)
      throw std::runtime_error("poll: " + std::string(std::strerror(errno)));
    alignas(inotify_event) char events[4096];
    while (::read(fd, events, sizeof events) > 0) {}
  }
  return true;
}

// Appended, not prefixed: GCC 12 warns, wrongly, about string literal + std::string.
std::string quoted(const std::filesystem::path& path) {
  std::string s = "'";
  s += path.string();
  s += "'";
  return s;
}

std::filesystem::path TempDir::write(const std::string& name, const std::string& bytes) const {
  const std::filesystem::path p = path_ / name;
  std::ofstream(p, std::ios::binary) << bytes;
  return p;
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

std::vector<std::string> filesUnder(const std::filesystem::path& dir, const std::string& except) {
  std::vector<std::string> out;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir))
    if (e.is_regular_file() && e.path().filename() != except)
      out.push_back(std::filesystem::relative(e.path(), dir).generic_string());
  std::sort(out.begin(), out.end());
  return out;
}

void expectSameFiles(const std::filesystem::path& a, const std::filesystem::path& b, const std::string& except) {
  const std::vector<std::string> files = filesUnder(a, except);
  EXPECT_EQ(files, filesUnder(b, except)) << a << " against " << b;
  EXPECT_FALSE(files.empty()) << a;
  for (const std::string& f : files)
    EXPECT_TRUE(fileBytes(a / f) == fileBytes(b / f)) << f << " differs: " << a << " against " << b;
}

}  // namespace gimlod::test
