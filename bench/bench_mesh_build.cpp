// The mesh stage against a peer in the same run: for each input (cube spheres made from a global
// DEM with etopo_sphere, and any scans given), a discrete LOD chain made with meshoptimizer (the
// baseline: halving simplifications to under 1% of the triangles, each level cache- and
// fetch-optimized and coded with meshoptimizer's index and vertex codecs), then `gimlod build` at
// its defaults (or with --build-args). Each runs as its own process, so its time and peak RSS are
// its own. Prints, per input, gimlod's stages (wall and CPU seconds, peak RSS) and a summary
// table: triangles, seconds, M triangles per second per core (triangles / CPU seconds), peak RSS,
// charts, samples and bytes per input triangle, Hausdorff distance and flipped texels, and the
// ratio of gimlod's time to the baseline's.
//
//   bench_mesh_build [--dem DEM --cube-res N[,N...]] [--work DIR] [--build-args "ARGS"] [MESH...]
//   bench_mesh_build --baseline MESH     (one baseline run: prints its figures as one JSON line)
//
// --cube-res 158,312,625,1248 gives the 0.3M, 1.17M, 4.7M and 18.7M triangle spheres.
#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <glm/common.hpp>
#include <fmt/format.h>
#include <meshoptimizer.h>
#include <nlohmann/json.hpp>

#include "atlas/mesh/mesh_io.h"
#include "bench/guarded_main.h"
#include "runtime/atlas_view.h"

extern char** environ;

namespace fs = std::filesystem;

namespace {

struct ChildRun {
  int status = -1;
  double seconds = 0.0;
  double cpuSeconds = 0.0;
  uint64_t peakRssBytes = 0;
  std::string out;  // its stdout
};

// Runs argv as a child process, its stdout into a file read back (its stderr, the log, into the
// same name with ".log" added), and measures it with wait4.
ChildRun runChild(const std::vector<std::string>& argv, const fs::path& outFile) {
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  const std::string logFile = outFile.string() + ".log";
  posix_spawn_file_actions_addopen(&actions, 1, outFile.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, 2, logFile.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  ChildRun r;
  const auto t0 = std::chrono::steady_clock::now();
  pid_t pid = 0;
  const int err = posix_spawn(&pid, args[0], &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (err != 0) throw std::runtime_error(fmt::format("cannot run {}: {}", argv[0], std::strerror(err)));
  struct rusage ru {};
  if (wait4(pid, &r.status, 0, &ru) < 0) throw std::runtime_error("wait4 failed for " + argv[0]);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.cpuSeconds = double(ru.ru_utime.tv_sec) + 1e-6 * double(ru.ru_utime.tv_usec) + double(ru.ru_stime.tv_sec) +
                 1e-6 * double(ru.ru_stime.tv_usec);
  r.peakRssBytes = uint64_t(ru.ru_maxrss) * 1024;
  std::ifstream in(outFile);
  std::stringstream ss;
  ss << in.rdbuf();
  r.out = ss.str();
  return r;
}

// The baseline: read, then a chain of levels each half the triangles of the one before (the
// input first), down to under 1% of the input, each coded as meshoptimizer codes a mesh for
// transmission: positions quantized on a lattice of 2^18 steps across the bounding box's largest
// side (gimlod's default lattice is 2^18 steps across the diagonal), as integers. Prints
// {"triangles", "levels", "bytes", "seconds"} on one line.
int runBaseline(const fs::path& input) {
  const auto t0 = std::chrono::steady_clock::now();
  const gimlod::IndexedMesh mesh = gimlod::readMesh(input);
  std::vector<float> xyz;
  xyz.reserve(mesh.positions.size() * 3);
  glm::vec3 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
  for (const glm::vec3& p : mesh.positions) {
    xyz.insert(xyz.end(), {p.x, p.y, p.z});
    lo = glm::min(lo, p), hi = glm::max(hi, p);
  }
  const float extent = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z, 1e-30f});
  std::vector<uint32_t> lattice(xyz.size());
  for (size_t i = 0; i < xyz.size(); ++i)
    lattice[i] = uint32_t(std::lround(double(xyz[i] - lo[int(i % 3)]) / extent * double((1u << 18) - 1)));
  std::vector<uint32_t> indices;
  indices.reserve(mesh.triangles.size() * 3);
  for (const auto& t : mesh.triangles) indices.insert(indices.end(), t.begin(), t.end());
  const size_t vertices = mesh.positions.size();
  const size_t floor = std::max<size_t>(indices.size() / 100, 3 * 64);
  uint64_t bytes = 0;
  uint32_t levels = 0;
  std::vector<uint32_t> level = indices;
  for (;;) {
    std::vector<uint32_t> lod = level;
    meshopt_optimizeVertexCache(lod.data(), lod.data(), lod.size(), vertices);
    std::vector<uint32_t> remap(vertices);
    std::vector<uint32_t> packed(vertices * 3);
    const size_t used = meshopt_optimizeVertexFetchRemap(remap.data(), lod.data(), lod.size(), vertices);
    meshopt_remapIndexBuffer(lod.data(), lod.data(), lod.size(), remap.data());
    meshopt_remapVertexBuffer(packed.data(), lattice.data(), vertices, sizeof(uint32_t) * 3, remap.data());
    std::vector<unsigned char> ib(meshopt_encodeIndexBufferBound(lod.size(), used));
    std::vector<unsigned char> vb(meshopt_encodeVertexBufferBound(used, sizeof(uint32_t) * 3));
    bytes += meshopt_encodeIndexBuffer(ib.data(), ib.size(), lod.data(), lod.size());
    bytes += meshopt_encodeVertexBuffer(vb.data(), vb.size(), packed.data(), used, sizeof(uint32_t) * 3);
    ++levels;
    if (level.size() <= floor) break;
    std::vector<uint32_t> next(level.size());
    float error = 0.f;
    next.resize(meshopt_simplify(next.data(), level.data(), level.size(), xyz.data(), vertices, sizeof(float) * 3,
                                 level.size() / 2, 1e-2f, 0, &error));
    if (next.size() >= level.size()) break;  // nothing left to take away
    level = std::move(next);
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf(
      "%s\n",
      nlohmann::json({{"triangles", mesh.triangles.size()}, {"levels", levels}, {"bytes", bytes}, {"seconds", seconds}})
          .dump()
          .c_str());
  return 0;
}

struct Row {
  std::string name;
  uint64_t triangles = 0;
  double seconds = 0, cpuSeconds = 0, peakMiB = 0;
  uint32_t charts = 0;
  uint32_t roots = 0;  // the forest's roots once opened: top groups above the charts, or the charts
  double samplesPerTriangle = 0, bytesPerTriangle = 0, hausdorff = -1;
  uint64_t flipped = 0;
  double baseSeconds = 0, basePeakMiB = 0, baseBytesPerTriangle = 0;
};

std::vector<std::string> splitArgs(const std::string& s) {
  std::vector<std::string> out;
  std::istringstream in(s);
  for (std::string a; in >> a;) out.push_back(a);
  return out;
}

Row benchOne(const fs::path& self, const fs::path& gimlod, const fs::path& mesh, const fs::path& work,
             const std::string& buildArgs) {
  Row row;
  row.name = mesh.stem().string();
  const ChildRun base = runChild({self.string(), "--baseline", mesh.string()}, work / "baseline.json");
  if (base.status != 0) throw std::runtime_error("the baseline failed on " + mesh.string());
  const nlohmann::json b = nlohmann::json::parse(base.out);
  row.baseSeconds = base.seconds;
  row.basePeakMiB = double(base.peakRssBytes) / (1 << 20);
  const fs::path atlas = work / (row.name + ".atlas");
  fs::remove_all(atlas);
  std::vector<std::string> argv = {gimlod.string(), "build", mesh.string(), "-o", atlas.string()};
  for (const std::string& a : splitArgs(buildArgs)) argv.push_back(a);
  const ChildRun g = runChild(argv, work / "build.log");
  if (g.status != 0)
    throw std::runtime_error("gimlod build failed on " + mesh.string() + ": see " + (work / "build.log.log").string());
  std::ifstream in(atlas / "stats.json");
  const nlohmann::json st = nlohmann::json::parse(in);
  row.triangles = st["charting"]["triangles"].get<uint64_t>();
  row.seconds = g.seconds;
  row.cpuSeconds = g.cpuSeconds;
  row.peakMiB = double(g.peakRssBytes) / (1 << 20);
  row.charts = st["charts"].get<uint32_t>();
  const double tris = double(std::max<uint64_t>(row.triangles, 1));
  row.samplesPerTriangle = double(st["samples"].get<uint64_t>()) / tris;
  row.bytesPerTriangle = double(st["bytes_on_disk"].get<uint64_t>()) / tris;
  if (st["fidelity"].is_object()) row.hausdorff = st["fidelity"]["hausdorff_percent_of_diagonal"].get<double>();
  row.flipped = st["resample"]["flipped_texels"].get<uint64_t>();
  row.baseBytesPerTriangle = double(b["bytes"].get<uint64_t>()) / tris;
  std::printf("\n%s: %llu triangles\n\n| stage | wall s | CPU s | peak RSS MiB |\n|---|---:|---:|---:|\n",
              row.name.c_str(), static_cast<unsigned long long>(row.triangles));
  for (const nlohmann::json& s : st["stages"])
    std::printf("| %s | %.2f | %.2f | %.0f |\n", s["stage"].get<std::string>().c_str(), s["seconds"].get<double>(),
                s["cpu_seconds"].get<double>(), double(s["peak_rss_bytes"].get<uint64_t>()) / (1 << 20));
  std::fflush(stdout);
  {
    const gimlod::AtlasView view = gimlod::openAtlas(atlas);
    row.roots =
        view.hierarchy.groups.empty() ? view.hierarchy.chartCount() : uint32_t(view.hierarchy.groups.tops.size());
  }
  fs::remove_all(atlas);
  return row;
}

int run(int argc, char** argv) {
  CLI::App app{"gimlod's mesh stage against a meshoptimizer LOD chain, input by input"};
  std::string baseline, dem, cubeRes, buildArgs;
  fs::path work = fs::temp_directory_path() / "gimlod-bench-mesh-build";
  std::vector<std::string> meshes;
  app.add_option("--baseline", baseline, "Run the baseline alone on this mesh (one JSON line)");
  app.add_option("--dem", dem, "Global lat/long DEM for the spheres (etopo_sphere)");
  app.add_option("--cube-res", cubeRes, "Sphere cube resolutions, comma-separated (12 N^2 triangles each)");
  app.add_option("--work", work, "Scratch directory for the spheres and atlases")->capture_default_str();
  app.add_option("--build-args", buildArgs, "Extra arguments for gimlod build");
  app.add_option("meshes", meshes, "Scans (any format gimlod reads)");
  CLI11_PARSE(app, argc, argv);
  if (!baseline.empty()) return runBaseline(baseline);
  const fs::path self = fs::canonical("/proc/self/exe");
  const fs::path dir = self.parent_path();
  const fs::path gimlod = dir.parent_path() / "gimlod";
  if (!fs::exists(gimlod)) throw std::runtime_error("no gimlod next to the bench directory: " + gimlod.string());
  fs::create_directories(work);
  std::vector<fs::path> inputs;
  if (!cubeRes.empty()) {
    if (dem.empty()) throw std::runtime_error("--cube-res needs --dem");
    std::stringstream ss(cubeRes);
    for (std::string n; std::getline(ss, n, ',');) {
      const fs::path ply = work / ("sphere_" + n + ".ply");
      if (!fs::exists(ply)) {
        const ChildRun r = runChild(
            {(dir / "etopo_sphere").string(), dem, "-o", ply.string(), "--tessellation", "cube", "--cube-res", n},
            work / "sphere.log");
        if (r.status != 0) throw std::runtime_error("etopo_sphere failed for --cube-res " + n);
      }
      inputs.push_back(ply);
    }
  }
  for (const std::string& m : meshes) inputs.emplace_back(m);
  if (inputs.empty()) throw std::runtime_error("no input: give --dem and --cube-res, or meshes");
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  std::vector<Row> rows;
  for (const fs::path& in : inputs) rows.push_back(benchOne(self, gimlod, in, work, buildArgs));
  std::printf(
      "\n| input | triangles | gimlod s | CPU s | M tri/s/core | peak MiB | charts | roots | samples/tri | B/tri | "
      "Hausdorff %% | flipped | meshopt chain s | peak MiB | B/tri | gimlod / chain |\n"
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const Row& r : rows)
    std::printf(
        "| %s | %llu | %.2f | %.2f | %.3f | %.0f | %u | %u | %.1f | %.1f | %.4f | %llu | %.2f | %.0f | %.2f | %.2f |\n",
        r.name.c_str(), static_cast<unsigned long long>(r.triangles), r.seconds, r.cpuSeconds,
        double(r.triangles) / 1e6 / std::max(r.cpuSeconds, 1e-9), r.peakMiB, r.charts, r.roots, r.samplesPerTriangle,
        r.bytesPerTriangle, r.hausdorff, static_cast<unsigned long long>(r.flipped), r.baseSeconds, r.basePeakMiB,
        r.baseBytesPerTriangle, r.seconds / std::max(r.baseSeconds, 1e-9));
  std::printf("\n%u cores\n", cores);
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return guardedMain(argc, argv, run); }
