// Helpers shared by the tests: data locations and temporary directories.
#pragma once

#include <chrono>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>
#include <sstream>
#include <fstream>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

// Skips the current test (fails it where sharedDataRequired()) unless `present` holds.
#define GIMLOD_NEED_SHARED_DATA(present)                                                    \
  do {                                                                                      \
    if (!(present)) {                                                                       \
      if (::gimlod::test::sharedDataRequired()) FAIL() << "missing shared data: " #present; \
      GTEST_SKIP() << "no ../shared/data (" #present ")";                                   \
    }                                                                                       \
  } while (0)

namespace gimlod::test {

// ../shared/data (absent on a user's clone: tests that need it skip there, and fail in CI; see
// GIMLOD_NEED_SHARED_DATA).
std::filesystem::path sharedData();
bool haveSharedData();
// data/ inside the repository.
std::filesystem::path repoData();
// A real data file by its path under data/ (e.g. "meshes/bun_zipper.ply"): the copy shipped in
// the repository when there is one (the bunny, the Rainier tile), so a clone without ../shared
// runs the test too; else the one under ../shared/data.
std::filesystem::path realData(const std::string& relative);
bool haveRealData(const std::string& relative);
// Whether missing shared data must fail a test rather than skip it: in CI (CI=true) or with
// GIMLOD_REQUIRE_SHARED_DATA=1, so that real-data invariants never pass by being skipped.
bool sharedDataRequired();
// The build folder's cache of test atlases (build/test-cache), and the files of the libraries that
// build atlases, '|'-separated (their sizes and times name the cached scan atlases).
std::filesystem::path testCache();
std::string atlasLibraries();
// Path to the gimlod command-line app (for the cli and window tiers, whose binaries depend on it).
std::filesystem::path appPath();

// Under ThreadSanitizer, TBB runs on the calling thread only while this lives: libtbb is not
// built with the sanitizer, so its scheduler's own synchronisation looks like races. Fixtures
// that build an atlas only to test other threads (the page loader) hold one. Elsewhere a no-op.
class SerialTbbUnderTsan {
#if defined(__SANITIZE_THREAD__)
  tbb::global_control serial_{tbb::global_control::max_allowed_parallelism, 1};
#endif
};

// A fresh empty directory, removed when the object goes out of scope.
class TempDir {
 public:
  explicit TempDir(const std::string& tag = "gimlod");
  ~TempDir();
  const std::filesystem::path& path() const { return path_; }
  // Writes `bytes` to the file `name` in it; returns the file's path.
  std::filesystem::path write(const std::string& name, const std::string& bytes) const;

 private:
  std::filesystem::path path_;
};

// Waits until `ready()` holds: checks it now, then again each time a file in `dir` is created,
// written or moved in (inotify; a program that writes a row per frame wakes it each frame).
// Returns false when `timeout` passes first.
bool waitForFiles(const std::filesystem::path& dir, const std::function<bool()>& ready,
                  std::chrono::milliseconds timeout);

// A path in single quotes for the shell.
std::string quoted(const std::filesystem::path& path);

// A file's whole contents ("" if it cannot be read).
std::string fileBytes(const std::filesystem::path& path);

// Runs a shell command; returns its exit status and captures stdout+stderr into `output`.
int runCommand(const std::string& command, std::string* output = nullptr);

// The files under dir (paths relative to it, sorted), but those named `except`.
std::vector<std::string> filesUnder(const std::filesystem::path& dir, const std::string& except = "");
// Expects dirs a and b to hold the same files with the same bytes, but those named `except`.
void expectSameFiles(const std::filesystem::path& a, const std::filesystem::path& b, const std::string& except);

// A CSV file as the commands write it: a header row, then rows of comma-separated fields.
struct Csv {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  size_t col(const std::string& name) const {
    for (size_t i = 0; i < header.size(); ++i)
      if (header[i] == name) return i;
    ADD_FAILURE() << "no column " << name;
    return 0;
  }
  double num(size_t row, const std::string& name) const { return std::stod(rows[row][col(name)]); }
};

inline std::vector<std::string> splitComma(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(item);
  if (!line.empty() && line.back() == ',') out.push_back("");
  return out;
}

inline Csv readCsv(const std::filesystem::path& p) {
  Csv c;
  std::ifstream in(p);
  std::string line;
  if (std::getline(in, line)) c.header = splitComma(line);
  while (std::getline(in, line))
    if (!line.empty()) c.rows.push_back(splitComma(line));
  return c;
}

}  // namespace gimlod::test
