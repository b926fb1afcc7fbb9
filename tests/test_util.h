// Helpers shared by the tests: data locations and temporary directories.
#pragma once

#include <filesystem>
#include <string>

namespace gimlod::test {

// ../shared/data (may be absent on a user's clone: tests that need it skip).
std::filesystem::path sharedData();
bool haveSharedData();
// data/ inside the repository.
std::filesystem::path repoData();
// Path to the gimlod command-line app.
std::filesystem::path appPath();

// A fresh empty directory, removed when the object goes out of scope.
class TempDir {
 public:
  explicit TempDir(const std::string& tag = "gimlod");
  ~TempDir();
  const std::filesystem::path& path() const { return path_; }
 private:
  std::filesystem::path path_;
};

// Runs a shell command; returns its exit status and captures stdout+stderr into `output`.
int runCommand(const std::string& command, std::string* output = nullptr);

}  // namespace gimlod::test
