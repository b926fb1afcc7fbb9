// libFuzzer harness for the chart file reader: open, then read every level of every channel the
// header announces; and the writer that carries a partial chart file on (a shard's imagery,
// ChartFileWriter::commitPartial). Bad input must end in InputError.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <stdexcept>

#include "core/atlas_format.h"
#include "tests/fuzz/fuzz_input.h"

// The input carried on as a partial chart file, as a merge carries on a shard's, into a colour
// chart of the shape its header gives (version, chart size, block intervals and levels at bytes 4,
// 8, 12 and 16; charts of at most 1025 samples in blocks of 8 intervals or more, so the directory
// stays small). The reader refuses a partial file (its missing blocks), so this does not go through it.
namespace {

void resumeAsPartial(const uint8_t* data, size_t size, const std::filesystem::path& path) {
  if (size < 24) return;
  auto word = [&](size_t at) {
    uint32_t v = 0;
    std::memcpy(&v, data + at, 4);
    return v;
  };
  const uint32_t version = word(4), chartSize = word(8), blockIntervals = word(12), levels = word(16);
  if (chartSize > 1025 || blockIntervals < 8) return;
  gimlod::ChartCoding coding;
  coding.compressed = version == 3;
  const gimlod::ChartFileShape shape{chartSize, blockIntervals, levels, 1u << gimlod::kChannelColours};
  try {
    const gimlod::ChartFileWriter resumed(path.parent_path() / "resumed.bin", shape, coding, path);
  } catch (const std::invalid_argument&) {
    // a shape no writer writes
  } catch (const gimlod::InputError&) {}
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = gimlod::fuzz::writeInput("chart.bin", data, size);
  try {
    resumeAsPartial(data, size, path);
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
