// Streaming mesh input: PLY (ASCII, binary little- and big-endian, faces or triangle strips), OBJ,
// OFF and STL (ASCII and binary). Triangles are delivered in chunks to a sink, so the faces of a
// mesh larger than RAM can be streamed; indexed formats keep only their vertex array in memory.
// Bad input throws InputError naming the file and the problem; repairable defects (non-finite
// coordinates, degenerate and duplicate triangles) are dropped and counted in MeshReadStats.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include "core/atlas_format.h"

namespace gimlod {

enum class MeshFormat : uint8_t { kPly, kObj, kOff, kStl };

// Source vertex index of a corner with no index in the file (STL, grid cells).
inline constexpr uint32_t kNoVertex = std::numeric_limits<uint32_t>::max();

// One triangle as delivered to a sink. Corners are in the file's winding order (triangle strips
// are decoded with alternating winding, so all triangles of a strip share its orientation).
struct MeshTriangle {
  std::array<glm::vec3, 3> p;    // positions, as stored in the file (converted to float)
  std::array<glm::u8vec4, 3> c;  // per-vertex RGBA colours; opaque white when the mesh has none
  std::array<uint32_t, 3> v;     // source vertex indices (0-based); kNoVertex for STL
};

// Axis-aligned box; empty (min > max) until extended.
struct MeshBounds {
  glm::vec3 min{std::numeric_limits<float>::infinity()};
  glm::vec3 max{-std::numeric_limits<float>::infinity()};
  bool empty() const { return !(min.x <= max.x && min.y <= max.y && min.z <= max.z); }
  void extend(const glm::vec3& p);
  void extend(const MeshBounds& b);
};

// What is known about a mesh before its faces are read.
struct MeshInfo {
  MeshFormat format = MeshFormat::kPly;
  std::string formatName;         // e.g. "PLY binary big-endian", "OBJ", "STL binary"
  uint64_t vertices = 0;          // vertex records (0 for STL)
  uint64_t faces = 0;             // face records: polygons, strips or facets (declared or counted)
  uint64_t triangleEstimate = 0;  // expected triangles before repair (for sizing; not exact)
  bool hasColours = false;        // per-vertex colours present
  bool boundsKnown = false;       // bounds below are valid
  MeshBounds bounds;              // of all finite vertex positions (unreferenced ones included)
};

struct MeshReadOptions {
  uint32_t chunkTriangles = 1u << 16;  // triangles per TriangleSink::consume call; >= 1
  bool removeDuplicates = true;        // drop triangles repeating a triangle's 3 vertices
  // Memory bound of the duplicate set (16-byte slots at most 70% full: 23 to 46 bytes per
  // triangle). When full, later triangles are still checked against it but no longer added:
  // stats.duplicateCheckComplete = false. 0 means no bound.
  uint64_t duplicateSetBytes = 1ull << 30;
  // Bound on the in-memory vertex array of indexed formats (16 bytes per vertex with colours,
  // 12 without); exceeding it is an InputError. 0 means no bound.
  uint64_t maxVertexBytes = 0;
};

// Counts of what was read and repaired. Invariant:
// trianglesRead == trianglesOut + droppedNonFinite + droppedDegenerate + droppedDuplicate.
struct MeshReadStats {
  MeshInfo info;
  uint64_t vertices = 0;                // vertex records read
  uint64_t nonFiniteVertices = 0;       // vertices with a NaN or infinite coordinate
  uint64_t faces = 0;                   // face records read (polygons, strips, facets)
  uint64_t shortFaces = 0;              // faces with fewer than 3 corners (skipped, no triangles)
  uint64_t polygonsFanned = 0;          // faces with more than 3 corners, fan-triangulated
  uint64_t strips = 0;                  // triangle strips decoded (a -1 index starts a new one)
  uint64_t trianglesRead = 0;           // candidate triangles after strip / fan decoding
  uint64_t trianglesOut = 0;            // triangles delivered to the sink
  uint64_t droppedNonFinite = 0;        // used a vertex with a NaN or infinite coordinate
  uint64_t droppedDegenerate = 0;       // repeated vertex index, or exactly zero area
  uint64_t droppedStripDegenerate = 0;  // of droppedDegenerate: inside strips (strip turns)
  uint64_t droppedDuplicate = 0;        // same 3 vertices (any order) as an earlier triangle
  bool duplicateCheckComplete = true;   // false if the duplicate set reached its memory bound
  bool hasColours = false;
  MeshBounds bounds;  // of the delivered triangles
  uint64_t bytesRead = 0;
  uint64_t vertexArrayBytes = 0;   // memory held for the vertex array
  uint64_t duplicateSetBytes = 0;  // memory held for the duplicate set
  double seconds = 0.0;
  std::vector<std::string> warnings;  // non-fatal issues (trailing data, unused elements, ...)
};

// Receives triangles in chunks. The pointers are valid only during the call.
class TriangleSink {
 public:
  virtual ~TriangleSink() = default;
  // Called once before the first consume(). For PLY and OFF the vertex array has been read, so
  // info.boundsKnown is true; for OBJ and STL it is false (use probeMesh for a pre-pass).
  virtual void begin(const MeshInfo& /*info*/) {}
  virtual void consume(const MeshTriangle* tris, size_t n) = 0;
};

// Detects the format from the first bytes (atlas/mesh/mesh_format.h: "ply", "OFF", STL "solid"
// and "facet" or its size, OBJ "v " lines), else from the extension (.ply .obj .off .stl, any
// case); the readers read a file as its content shows and warn when its extension names another
// format. Throws InputError if the file cannot be opened, is empty, or is not one of the
// supported formats.
MeshInfo detectMesh(const std::filesystem::path& path);

// detectMesh plus the bounds and a triangle estimate. Cost: PLY and OFF read the header and the
// vertex section; OBJ and STL need a full pass over the file. Throws InputError like streamMesh.
MeshInfo probeMesh(const std::filesystem::path& path, const MeshReadOptions& options = {});

// Streams every valid triangle of the mesh to the sink, dropping and counting triangles that use
// non-finite vertices, degenerate triangles and duplicates (checked in that order; duplicates by
// vertex index for indexed formats, by exact positions for STL). Memory: the vertex array of
// indexed formats, the duplicate set and one chunk; faces are never all held.
// Throws InputError "<file>: <problem>" on: unreadable, empty or truncated files, bad headers,
// unknown PLY property types, unsupported format variants, a face index outside the vertex
// array (naming the face), vertex counts that cannot fit the file, bad options. Exceptions
// thrown by the sink propagate.
MeshReadStats streamMesh(const std::filesystem::path& path, TriangleSink& sink, const MeshReadOptions& options = {});
// The same with a callback per chunk.
MeshReadStats streamMesh(const std::filesystem::path& path,
                         const std::function<void(std::span<const MeshTriangle>)>& consume,
                         const MeshReadOptions& options = {});

// A whole mesh in memory, for small meshes and tests.
struct IndexedMesh {
  std::vector<glm::vec3> positions;                // every vertex of the file, in file order (STL: welded
                                                   // exactly equal positions, in first-use order)
  std::vector<glm::u8vec4> colours;                // empty, or one per position
  std::vector<std::array<uint32_t, 3>> triangles;  // after repair, in file order
  MeshReadStats stats;
};

// Reads the whole mesh (streamMesh's checks and repairs). Throws as streamMesh.
IndexedMesh readMesh(const std::filesystem::path& path, const MeshReadOptions& options = {});

// Lower-case name of a format ("ply", "obj", "off", "stl").
const char* meshFormatName(MeshFormat f);

}  // namespace gimlod
