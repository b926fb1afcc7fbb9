// libFuzzer harness for the chart file reader: open, then read every level of every channel the
// header announces. Bad input must end in InputError.
#include <cstddef>
#include <cstdint>

#include "core/atlas_format.h"
#include "tests/fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = gimlod::fuzz::writeInput("chart.bin", data, size);
  try {
    const gimlod::ChartFileReader r(path);
    for (uint32_t level = 0; level < r.levels(); ++level) {
      if (r.hasChannel(gimlod::kChannelHeights)) (void)r.readLevelHeights(level);
      if (r.hasChannel(gimlod::kChannelPositions)) (void)r.readLevelPositions(level);
      if (r.hasChannel(gimlod::kChannelNormals)) (void)r.readLevelNormals(level);
      if (r.hasChannel(gimlod::kChannelColours)) (void)r.readLevelColours(level);
    }
  } catch (const gimlod::InputError&) {}
  return 0;
}
