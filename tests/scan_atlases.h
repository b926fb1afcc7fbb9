// The shared real scans (../shared/data/meshes) and their atlases, built through the same library
// call as `gimlod build MESH -o ATLAS` at the default mesh options (patches by the triangle count,
// chart size by the input's density, the chart repair to the default sampling error),
// at most once per test executable per scan and kind of build (kept across its processes in the
// build folder). Used by the pipeline's scan tests (tests/pipeline/scan_atlas_test.cpp,
// adapt_root_floor_test.cpp), the GL crack tests (tests/gl/scan_crack_gl_test.cpp) and the export
// command's (tests/cli/scan_export_cli_test.cpp).
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <fcntl.h>
#include <nlohmann/json.hpp>
#include <sys/file.h>
#include <unistd.h>

#include "pipeline/build.h"
#include "tests/test_util.h"

namespace gimlod::test {

struct SharedScan {
  std::string name;  // test-name suffix
  std::string file;  // under data/meshes (see sharedScanPath)
};

// Every shared scan: the bunny (5 holes), igea (triangle strips), turbine blade, horse, armadillo.
inline const std::vector<SharedScan>& sharedScans() {
  static const std::vector<SharedScan> scans = {{"bunny", "bun_zipper.ply"},
                                                {"igea", "igea.ply"},
                                                {"turbineblade", "turbineblade.ply"},
                                                {"horse", "horse.ply"},
                                                {"armadillo", "armadillo.obj"}};
  return scans;
}

inline std::vector<std::string> sharedScanNames() {
  std::vector<std::string> names;
  for (const SharedScan& s : sharedScans()) names.push_back(s.name);
  return names;
}

inline const SharedScan& sharedScan(const std::string& name) {
  for (const SharedScan& s : sharedScans())
    if (s.name == name) return s;
  throw std::invalid_argument("no shared scan " + name);
}

// The scan's file: the shipped copy for the bunny, else under ../shared/data/meshes.
inline std::filesystem::path sharedScanPath(const std::string& name) {
  return realData("meshes/" + sharedScan(name).file);
}

// True when the scan file is there (only the bunny is shipped; the others are shared data).
inline bool haveSharedScan(const std::string& name) { return std::filesystem::exists(sharedScanPath(name)); }

struct BuiltScanAtlas {
  std::filesystem::path dir;  // the atlas directory
  nlohmann::json stats;       // what buildAtlas returned (= dir/stats.json)
  bool fidelity = false;      // stats hold the Hausdorff figures
  double seconds = 0.0;       // build time
};

// Where a scan's atlas is kept for the other test processes: under testCache(), named for
// the scan, the kind of build and the sizes and modification times of the libraries that build
// atlases (atlasLibraries()). Every test binary that builds scan atlases links those same
// library files, so the binaries share one build of each scan, and a change to the libraries
// renames the folder: no test reads an atlas that older code made.
inline std::filesystem::path cachedScanAtlasPath(const std::string& name, bool withFidelity) {
  namespace fs = std::filesystem;
  uint64_t stamp = 1469598103934665603ull;  // FNV-1a over (size, time) of each library
  const std::string libraries = atlasLibraries();
  for (size_t begin = 0; begin <= libraries.size();) {
    const size_t end = std::min(libraries.find('|', begin), libraries.size());
    std::error_code ec;
    const fs::path lib = libraries.substr(begin, end - begin);
    const uint64_t size = fs::file_size(lib, ec);
    const uint64_t time = ec ? 0 : uint64_t(fs::last_write_time(lib, ec).time_since_epoch().count());
    for (const uint64_t v : {ec ? 0 : size, time})
      for (int byte = 0; byte < 8; ++byte) stamp = (stamp ^ ((v >> (8 * byte)) & 0xff)) * 1099511628211ull;
    begin = end + 1;
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(stamp));
  return testCache() / ("scans-" + std::string(hex)) / (name + (withFidelity ? "_fidelity" : "") + ".atlas");
}

// The atlas of scan `name` at the default mesh options, built once for the test executables: the
// first process that asks builds it (others wait on a lock) into the cache (cachedScanAtlasPath),
// and every later process reads it there. What buildAtlas returned and the
// build time are kept beside the atlas (dir/build.json, written last: an atlas without it, from a
// build killed halfway, is built again), so `stats` is always buildAtlas's own return.
// withFidelity: the build measures the two-sided Hausdorff distance (about half the build time);
// a build without it is reused only when fidelity is not asked for, so the tests ask alike (all
// with it: one build serves both executables). With GIMLOD_TEST_SCAN_ATLASES set, a complete
// atlas in that folder (another build folder's scans-* cache of the same sources) is used rather
// than built. Throws what buildAtlas throws.
inline const BuiltScanAtlas& scanAtlas(const std::string& name, bool withFidelity) {
  namespace fs = std::filesystem;
  static std::map<std::string, BuiltScanAtlas> built;
  auto it = built.find(name);
  if (it != built.end() && (it->second.fidelity || !withFidelity)) return it->second;
  // The cached build at dir, if complete.
  auto cached = [&](const fs::path& dir, bool fidelity) -> const BuiltScanAtlas* {
    if (!fs::exists(dir / "build.json")) return nullptr;
    const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir / "build.json"));
    return &(built[name] = BuiltScanAtlas{dir, j.at("stats"), fidelity, j.at("seconds").get<double>()});
  };
  for (const bool fidelity : {true, false})
    if (fidelity || !withFidelity)
      if (const BuiltScanAtlas* b = cached(cachedScanAtlasPath(name, fidelity), fidelity)) return *b;
  // Atlases another build folder made of the same sources (GIMLOD_TEST_SCAN_ATLASES: .ci/run
  // points the sanitizer builds at the Release build's, made moments before from the same clone).
  if (const char* shared = std::getenv("GIMLOD_TEST_SCAN_ATLASES"); shared && *shared) {
    for (const bool fidelity : {true, false})
      if (fidelity || !withFidelity)
        if (const BuiltScanAtlas* b =
                cached(fs::path(shared) / (name + (fidelity ? "_fidelity" : "") + ".atlas"), fidelity))
          return *b;
  }
  const fs::path dir = cachedScanAtlasPath(name, withFidelity);
  if (!fs::exists(dir.parent_path())) {
    // What earlier builds kept is stale: removed (and what the per-executable caches kept before).
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(testCache(), ec)) {
      const std::string entry = e.path().filename().string();
      const bool ours = entry.rfind("scans-", 0) == 0 || entry.rfind("gimlod_tests-", 0) == 0 ||
                        entry.rfind("gimlod_gl_tests-", 0) == 0;
      if (ours && e.path() != dir.parent_path()) fs::remove_all(e.path(), ec);
    }
  }
  fs::create_directories(dir.parent_path());
  // One builder at a time per atlas; the lock goes with the descriptor (and with the process, even
  // by a crash).
  struct Lock {
    int fd;
    ~Lock() {
      if (fd >= 0) ::close(fd);
    }
  } lock{::open((dir.string() + ".lock").c_str(), O_CREAT | O_RDWR, 0644)};
  if (lock.fd >= 0) ::flock(lock.fd, LOCK_EX);
  if (const BuiltScanAtlas* b = cached(dir, withFidelity)) return *b;  // built while waiting
  MeshBuildOptions o;                                                  // the defaults of `gimlod build` for meshes
  o.input = sharedScanPath(name);
  o.output = dir;
  o.measureFidelity = withFidelity;
  const auto t0 = std::chrono::steady_clock::now();
  nlohmann::json j;
  j["stats"] = buildAtlas(o);
  j["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::ofstream(dir / "build.json") << j.dump();
  return *cached(dir, withFidelity);
}

}  // namespace gimlod::test
