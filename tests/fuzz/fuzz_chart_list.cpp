// libFuzzer harness for the chart list file of a version 3 manifest (charts.json.zst, one zstd
// frame of JSON): the input is the list file beside a fixed manifest; bad input must end in
// InputError.
#include <cstddef>
#include <cstdint>
#include <string>

#include "core/atlas_format.h"
#include "tests/fuzz/fuzz_input.h"

namespace {

const std::string kManifest = R"({
  "format": "gimlod-atlas", "version": 3, "kind": "geometry", "chartSize": 65, "blockIntervals": 64,
  "chartsX": 300, "chartsY": 1, "spacing": [1.0, 1.0],
  "compression": {"codec": "lorenzo-zstd"},
  "hierarchy": {"file": "hierarchy.bin", "depth": 2, "maxNodeResLog2": 6, "minNodeResLog2": 2},
  "chartList": "charts.json.zst"
})";

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  gimlod::fuzz::writeInput(gimlod::kManifestName, reinterpret_cast<const uint8_t*>(kManifest.data()), kManifest.size());
  gimlod::fuzz::writeInput(gimlod::kChartListName, data, size);
  try {
    const gimlod::AtlasManifest m = gimlod::readManifest(gimlod::fuzz::scratchDirectory());
    // What the readers of a manifest rely on once it is accepted.
    if (m.charts.empty()) __builtin_trap();
    for (size_t i = 0; i < m.charts.size(); ++i) {
      const gimlod::ChartInfo& c = m.charts[i];
      if (c.id != i || c.file.empty() || c.finestLevel > m.intervalsLog2()) __builtin_trap();
      for (const gimlod::RootNeighbour& n : c.neighbours) {
        if (n.chart >= int32_t(m.charts.size()) || n.edge > 3) __builtin_trap();
      }
    }
  } catch (const gimlod::InputError&) {}
  return 0;
}
