// What a build's input file is, told from its content: the mesh formats by their headers, and
// anything else handed to GDAL as a raster.
#pragma once

#include <filesystem>

namespace gimlod {

enum class InputKind { Ply, Off, Stl, Obj, Raster };

// Whether the kind is one of the mesh formats.
inline bool isMesh(InputKind kind) { return kind != InputKind::Raster; }

// The kind's name: "PLY", "OFF", "STL", "OBJ" or "raster".
const char* inputKindName(InputKind kind);

// Detects the input kind from the first bytes: PLY ("ply" line), OFF ("OFF", "COFF", "NOFF",
// "STOFF", ... line), binary STL (80-byte header and a triangle count matching the file size),
// ASCII STL ("solid" then "facet"), OBJ (text with "v " or "f " lines); anything else is a
// raster for GDAL. The extension (.ply .off .stl .obj, any case) decides where the content does
// not ("solid" with no facet yet, a file that cannot be opened). Throws InputError naming the
// file when it is empty.
InputKind detectInputKind(const std::filesystem::path& path);

}  // namespace gimlod
