// Which mesh format a file holds, told from its first bytes, with its extension as the fallback:
// shared by the mesh reader (atlas/mesh/mesh_io.h) and the build's input detection
// (pipeline/input_kind.h), so both read a file the same way whatever it is called.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string_view>

#include "atlas/mesh/mesh_io.h"

namespace gimlod {

// How many leading bytes meshFormatOfContent looks at (fewer when the file is shorter).
inline constexpr size_t kMeshFormatHeadBytes = 4096;

// The format the content shows: PLY ("ply" alone on the first line), OFF ("OFF", "COFF",
// "NOFF", "STOFF", ... as the first word after '#' comment lines), ASCII STL ("solid NAME" then
// "facet" or "endsolid"), binary STL (an 80-byte header and a little-endian triangle count n in a
// file of 84 + 50 n bytes), OBJ (text without NUL bytes with a line starting "v " or "f ").
// head: the file's first bytes; fileSize: its full size. None when the content shows none of
// them (e.g. "solid" with no facet yet, or a truncated header).
std::optional<MeshFormat> meshFormatOfContent(std::string_view head, uint64_t fileSize);

// The format the extension names (.ply .obj .off .stl, any case); none for any other.
std::optional<MeshFormat> meshFormatOfExtension(const std::filesystem::path& path);

}  // namespace gimlod
