// libFuzzer harness for the atlas manifest reader (atlas.json): bad input must end in InputError.
#include <cstddef>
#include <cstdint>

#include "core/atlas_format.h"
#include "tests/fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  gimlod::fuzz::writeInput(gimlod::kManifestName, data, size);
  try {
    const gimlod::AtlasManifest m = gimlod::readManifest(gimlod::fuzz::scratchDirectory());
    // What the readers of a manifest rely on once it is accepted.
    if (!gimlod::isChartSizeValid(m.chartSize)) __builtin_trap();
    if (m.imagery.present && m.imagery.scaleLog2 > gimlod::kMaxImageryScaleLog2) __builtin_trap();
    for (const gimlod::ChartInfo& c : m.charts) {
      if (m.imagery.present && c.imageryFile.empty()) __builtin_trap();
      for (const gimlod::RootNeighbour& n : c.neighbours) {
        if (n.chart >= int32_t(m.charts.size()) || n.edge > 3) __builtin_trap();
      }
    }
  } catch (const gimlod::InputError&) {}
  return 0;
}
