// The shared real scans (../shared/data/meshes) and their atlases, built through the same library
// call as `gimlod build MESH -o ATLAS` at the default mesh options (patches by the triangle count,
// chart size by the input's density, the chart repair to the default sampling error),
// at most once per test process per scan and kind of build. Used by the CPU scan tests
// (tests/unit/scan_atlas_test.cpp) and the GL crack tests (tests/gl/scan_crack_gl_test.cpp).
#pragma once

#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

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

// The atlas of scan `name` at the default mesh options, built once per process into a temporary
// directory that lives until exit. withFidelity: the build measures the two-sided Hausdorff
// distance (about half the build time); a build without it is reused only when fidelity is not
// asked for. Throws what buildAtlas throws.
inline const BuiltScanAtlas& scanAtlas(const std::string& name, bool withFidelity) {
  static TempDir dir("gimlod-scan-atlases");
  static std::map<std::string, BuiltScanAtlas> built;
  auto it = built.find(name);
  if (it != built.end() && (it->second.fidelity || !withFidelity)) return it->second;
  MeshBuildOptions o;  // the defaults of `gimlod build` for meshes
  o.input = sharedScanPath(name);
  o.output = dir.path() / (name + (withFidelity ? "_fidelity" : "") + ".atlas");
  o.measureFidelity = withFidelity;
  BuiltScanAtlas b;
  const auto t0 = std::chrono::steady_clock::now();
  b.stats = buildAtlas(o);
  b.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  b.dir = o.output;
  b.fidelity = withFidelity;
  return built[name] = std::move(b);
}

}  // namespace gimlod::test
