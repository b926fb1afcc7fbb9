#include "pipeline/input_kind.h"

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>
#include <string_view>
#include <system_error>

#include "atlas/mesh/mesh_format.h"
#include "core/atlas_format.h"

namespace fs = std::filesystem;

namespace gimlod {
namespace {

InputKind kindOf(MeshFormat f) {
  switch (f) {
    case MeshFormat::kPly: return InputKind::Ply;
    case MeshFormat::kOff: return InputKind::Off;
    case MeshFormat::kStl: return InputKind::Stl;
    case MeshFormat::kObj: return InputKind::Obj;
  }
  return InputKind::Raster;
}

// The kind the extension names; Raster for any other extension.
InputKind kindFromExtension(const fs::path& path) {
  const std::optional<MeshFormat> f = meshFormatOfExtension(path);
  return f ? kindOf(*f) : InputKind::Raster;
}

}  // namespace

const char* inputKindName(InputKind kind) {
  switch (kind) {
    case InputKind::Ply: return "PLY";
    case InputKind::Off: return "OFF";
    case InputKind::Stl: return "STL";
    case InputKind::Obj: return "OBJ";
    case InputKind::Raster: return "raster";
  }
  return "?";
}

InputKind detectInputKind(const fs::path& path) {
  const InputKind hint = kindFromExtension(path);
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return hint;  // note: the build's reader names what is wrong
  const uint64_t size = fs::file_size(path, ec);
  if (ec) return hint;
  if (size == 0)
    throw InputError(path.string() + ": empty file (expected a mesh: PLY, OBJ, OFF or STL, or a raster GDAL reads)");
  std::ifstream in(path, std::ios::binary);
  if (!in) return hint;
  std::string head(size_t(std::min<uint64_t>(size, kMeshFormatHeadBytes)), '\0');
  in.read(head.data(), std::streamsize(head.size()));
  head.resize(size_t(in.gcount()));
  if (const std::optional<MeshFormat> f = meshFormatOfContent(head, size)) return kindOf(*f);
  return hint;  // e.g. "solid" with no facet yet, or a broken mesh: its reader names the problem
}

}  // namespace gimlod
