// libFuzzer harness for the hierarchy file reader (hierarchy.bin): bad input must end in
// InputError.
#include <cstddef>
#include <cstdint>

#include "core/atlas_format.h"
#include "hierarchy/hierarchy.h"
#include "tests/fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = gimlod::fuzz::writeInput("hierarchy.bin", data, size);
  try {
    (void)gimlod::readHierarchy(path);
  } catch (const gimlod::InputError&) {}
  return 0;
}
