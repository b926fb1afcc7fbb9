// libFuzzer harness for the height block decoder: any bytes end in decoded heights or a
// CodecError, for every block side the atlas uses.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/block_codec.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  for (uint32_t side : {65u, 17u, 3u}) {
    std::vector<float> out(size_t(side) * side);
    try {
      gimlod::decodeHeights({data, size}, side, out);
    } catch (const gimlod::CodecError&) {
    }
  }
  try {
    (void)gimlod::blockQuantization({data, size});
  } catch (const gimlod::CodecError&) {
  }
  return 0;
}
