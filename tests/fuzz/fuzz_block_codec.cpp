// libFuzzer harness for the block decoders: any bytes end in decoded samples or a CodecError, for
// every block side the atlas uses and every kind of block (heights, positions, normals of either
// prediction, border normals, colours).
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/block_codec.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::span<const uint8_t> in(data, size);
  for (uint32_t side : {67u, 65u, 17u, 11u, 3u}) {
    const size_t n = size_t(side) * side;
    std::vector<float> floats(3 * n);
    std::vector<std::array<uint8_t, 4>> bytes(n);
    try {
      gimlod::decodeHeights(in, side, std::span<float>(floats.data(), n));
    } catch (const gimlod::CodecError&) {}
    try {
      gimlod::decodePositions(in, side, floats);
    } catch (const gimlod::CodecError&) {}
    try {
      gimlod::decodeNormals(in, side, bytes);
    } catch (const gimlod::CodecError&) {}
    try {
      gimlod::decodeColours(in, side, bytes);
    } catch (const gimlod::CodecError&) {}
    try {
      gimlod::decodeBorderNormals(in, side, bytes);
    } catch (const gimlod::CodecError&) {}
  }
  try {
    (void)gimlod::blockQuantization(in);
  } catch (const gimlod::CodecError&) {}
  return 0;
}
