// The out-of-core charting stages alone, for profiling: gridify a mesh (or reuse a grid
// directory), then cluster its cells into a chart layout; prints each stage's wall and CPU time
// and peak RSS, and the charting's own breakdown. --check also validates the layout
// (validatePatchLayout) and prints a digest of it, to compare the layouts of two builds.
//
//   chart_cells MESH_OR_GRID_DIR [--grid DIR] [--charts N] [--max-memory BYTES] [--threads N]
//               [--check 1]
#include <cstdio>
#include <filesystem>
#include <string>

#include "atlas/mesh/charting.h"
#include "atlas/mesh/gridify.h"
#include "core/stage_meter.h"

namespace {

// FNV-1a over the layout's arrays.
uint64_t digest(const gimlod::PatchLayout& l) {
  uint64_t h = 1469598103934665603ull;
  auto bytes = [&](const void* p, size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  };
  bytes(l.positions.data(), l.positions.size() * sizeof(l.positions[0]));
  bytes(l.colours.data(), l.colours.size() * sizeof(l.colours[0]));
  bytes(l.triangles.data(), l.triangles.size() * sizeof(l.triangles[0]));
  for (const gimlod::Patch& p : l.patches) {
    bytes(p.triangles.data(), p.triangles.size() * 4);
    for (const gimlod::PatchSide& s : p.sides) {
      bytes(s.vertices.data(), s.vertices.size() * 4);
      bytes(&s.neighbourPatch, 4);
      bytes(&s.neighbourSide, 4);
    }
  }
  return h;
}

void resetPeak() {
  if (std::FILE* f = std::fopen("/proc/self/clear_refs", "w")) {
    std::fputs("5", f);
    std::fclose(f);
  }
}

}  // namespace

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  if (argc < 2) {
    std::fprintf(stderr,
                 "usage: chart_cells MESH_OR_GRID_DIR [--grid DIR] [--charts N] [--max-memory BYTES] [--threads N]\n");
    return 2;
  }
  fs::path input = argv[1], grid = "chart_cells.grid";
  gimlod::ChartingOptions co;
  co.targetPatches = 128;
  gimlod::GridifyOptions go;
  bool check = false;
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--grid")
      grid = argv[i + 1];
    else if (a == "--charts")
      co.targetPatches = uint32_t(std::stoul(argv[i + 1]));
    else if (a == "--max-memory")
      go.maxMemoryBytes = std::stoull(argv[i + 1]);
    else if (a == "--threads")
      co.threads = unsigned(std::stoul(argv[i + 1]));
    else if (a == "--check")
      check = std::stoul(argv[i + 1]) != 0;
    else {
      std::fprintf(stderr, "chart_cells: unknown option %s\n", a.c_str());
      return 2;
    }
  }
  try {
    gimlod::StageMeter meter;
    if (!fs::is_directory(input)) {
      resetPeak();
      meter.start();
      const gimlod::GridifyResult r = gimlod::gridify(input, grid, go);
      const gimlod::StageTiming& s = meter.finish("gridify");
      std::printf("gridify   %8.2f s wall %8.2f s cpu  peak RSS %7.1f MiB  %llu cells, %llu triangles\n", s.seconds,
                  s.cpuSeconds, double(s.peakRssBytes) / (1 << 20), (unsigned long long)r.cells,
                  (unsigned long long)r.triangles);
    } else {
      grid = input;
    }
    resetPeak();
    meter.start();
    gimlod::ChartingStats st;
    const gimlod::PatchLayout l = gimlod::buildPatchLayoutFromCells(grid, co, &st);
    const gimlod::StageTiming& s = meter.finish("charting");
    std::printf(
        "charting  %8.2f s wall %8.2f s cpu  peak RSS %7.1f MiB  %zu patches (%u before fixing), "
        "%u cells, %u cell clusters (%u dissolved)\n"
        "          cells %.2f s, weld %.2f s, global cluster %.2f s, sides %.2f s; unfixed %u\n",
        s.seconds, s.cpuSeconds, double(s.peakRssBytes) / (1 << 20), l.patches.size(), st.chartsBeforeFixing, st.cells,
        st.cellClusters, st.cellClustersDissolved, st.cellSeconds, st.weldSeconds, st.clusterSeconds - st.cellSeconds,
        st.sidesSeconds, st.patchesUnfixed);
    std::printf("          %llu triangles, %llu vertices (%llu split), %llu non-manifold edges, %llu open edges\n",
                (unsigned long long)st.outputTriangles, (unsigned long long)st.outputVertices,
                (unsigned long long)st.verticesSplit, (unsigned long long)st.nonManifoldEdges,
                (unsigned long long)st.boundaryEdges);
    if (check) {
      const std::vector<std::string> errs = gimlod::validatePatchLayout(l);
      std::printf("check     digest %016llx, %zu validation errors\n", (unsigned long long)digest(l), errs.size());
      for (size_t i = 0; i < errs.size() && i < 10; ++i) std::printf("          %s\n", errs[i].c_str());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "chart_cells: %s\n", e.what());
    return 1;
  }
  return 0;
}
