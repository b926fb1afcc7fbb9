// libFuzzer harness for the mesh reader, one binary per format: the input is written with the
// format's extension (GIMLOD_FUZZ_MESH_EXTENSION), probed, then read whole. Bad input must end in
// InputError naming the file; anything else (a crash, a sanitizer report, another exception, an
// allocation beyond libFuzzer's limit) is a bug.
#include <cstddef>
#include <cstdint>

#include "atlas/mesh/mesh_io.h"
#include "core/atlas_format.h"
#include "tests/fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = gimlod::fuzz::writeInput(std::string("input") + GIMLOD_FUZZ_MESH_EXTENSION, data, size);
  gimlod::MeshReadOptions options;
  options.chunkTriangles = 7;            // many small chunks: the chunk seams are exercised
  options.duplicateSetBytes = 1u << 16;  // a full duplicate set is exercised too
  try {
    (void)gimlod::probeMesh(path, options);
  } catch (const gimlod::InputError&) {}
  try {
    const gimlod::IndexedMesh mesh = gimlod::readMesh(path, options);
    for (const auto& t : mesh.triangles) {
      for (uint32_t v : t) {
        if (v >= mesh.positions.size()) __builtin_trap();  // a triangle past the vertex array
      }
    }
    if (!mesh.colours.empty() && mesh.colours.size() != mesh.positions.size()) __builtin_trap();
  } catch (const gimlod::InputError&) {}
  return 0;
}
