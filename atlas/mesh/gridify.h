// Mesh atlas stage 1: stream a mesh's triangles into a uniform 3D grid of cell files on disk,
// under a memory cap, so that the next stage (per-cell clustering) can load one cell at a time.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "atlas/mesh/mesh_io.h"

namespace gimlod {

inline constexpr uint32_t kGridFormatVersion = 1;
inline constexpr const char* kGridManifestName = "grid.json";

struct GridifyOptions {
  // Memory cap for the whole stage (vertex array, duplicate set, cell buffers, read chunk), in
  // bytes; at least 64 MiB. The vertex array of an indexed mesh may use a quarter of it, the
  // duplicate set an eighth.
  uint64_t maxMemoryBytes = 4ull << 30;
  // Grid resolution target: about this many triangles per non-empty cell; at least 1.
  uint32_t targetTrianglesPerCell = 50000;
  // Share of maxMemoryBytes for the per-cell triangle buffers, in (0, 0.5]; at least 64 KiB.
  // Buffers are written to their cell files before their total would pass it.
  double bufferFraction = 0.5;
  // chunkTriangles and removeDuplicates are used; the memory bounds are set from the cap.
  MeshReadOptions read;
};

// One non-empty cell.
struct GridCell {
  uint32_t id = 0;                  // x + dims[0] * (y + dims[1] * z)
  std::array<uint32_t, 3> coord{};  // (x, y, z)
  uint64_t triangles = 0;
  std::string file;  // relative to the grid directory
};

// The grid directory's manifest (grid.json). Cell (x, y, z) covers
// origin + [x, x+1] * cellSize[0] (and likewise in y and z); a triangle belongs to the cell of its
// centroid (see cellOf).
struct GridManifest {
  uint32_t version = kGridFormatVersion;
  std::string source;  // the mesh file
  std::array<double, 3> origin{};
  std::array<double, 3> cellSize{1.0, 1.0, 1.0};
  std::array<uint32_t, 3> dims{1, 1, 1};
  bool hasColours = false;    // records carry per-vertex colours
  uint32_t recordBytes = 36;  // 9 float32 positions (+ 3 RGBA8 colours: 48)
  uint64_t triangles = 0;
  MeshBounds bounds;            // of the triangles
  std::vector<GridCell> cells;  // the non-empty cells, by id
  // Repairs made by the reader, for the pipeline's report.
  uint64_t trianglesRead = 0, droppedNonFinite = 0, droppedDegenerate = 0, droppedDuplicate = 0;
  bool duplicateCheckComplete = true;

  // The cell holding the triangle's centroid (computed in double, clamped into the grid).
  std::array<uint32_t, 3> cellOf(const MeshTriangle& t) const;
  uint32_t cellId(const std::array<uint32_t, 3>& c) const { return c[0] + dims[0] * (c[1] + dims[1] * c[2]); }
  // The box of a cell: {min, max}.
  std::array<std::array<double, 3>, 2> cellBox(const std::array<uint32_t, 3>& c) const;
};

struct GridifyResult {
  GridManifest manifest;
  MeshReadStats read;
  uint64_t cells = 0;  // non-empty cells
  uint64_t triangles = 0;
  uint64_t maxCellTriangles = 0;
  uint64_t bufferBudgetBytes = 0;  // bufferFraction * maxMemoryBytes
  uint64_t peakBufferedBytes = 0;  // largest total of allocated cell-buffer bytes
  uint64_t peakTrackedBytes = 0;   // vertex array + duplicate set + peak buffers + chunk
                                   // + cell table (an upper bound of this stage's heap)
  uint64_t flushRounds = 0;        // times the buffers reached the budget
  uint64_t cellWrites = 0;         // appends to cell files
  uint64_t bytesWritten = 0;
  bool probed = false;  // a bounds pre-pass was needed (OBJ, STL)
  double seconds = 0.0;
};

// Grid dimensions for `triangles` triangles in `bounds`: cubic cells sized so that a surface
// (area estimated as half the box's surface area) gives about targetPerCell triangles per cell;
// zero-extent axes get 1 cell; at most 1024 cells per axis and maxCells in all.
std::array<uint32_t, 3> chooseGridDims(const MeshBounds& bounds, uint64_t triangles, uint32_t targetPerCell,
                                       uint64_t maxCells = 1u << 20);

// Streams the mesh into outDir: grid.json plus cells/cell_NNNNNNNN.bin. Each cell file:
// "GLGC", u32 version, u32 recordBytes, u32 0, then the cell's triangles (recordBytes each:
// 9 float32 positions, then 3 RGBA8 colours when hasColours), little-endian. Cell files are
// written to temporary names and renamed; the directory is staged beside outDir and renamed into
// place, so a failure leaves no partial grid. outDir may be absent, empty, or an earlier grid.
// OBJ and STL need a bounds pre-pass (two reads); PLY and OFF are read once.
// Throws InputError on bad options, bad input (see streamMesh), no valid triangles, a vertex
// array over a quarter of the cap, or an unwritable outDir.
GridifyResult gridify(const std::filesystem::path& mesh, const std::filesystem::path& outDir,
                      const GridifyOptions& options = {});

// Reads and validates dir/grid.json. Throws InputError "<dir>/grid.json: <problem>".
GridManifest readGridManifest(const std::filesystem::path& dir);

// Loads one cell's triangles (v = kNoVertex; colours white if the grid has none). Throws
// InputError if the file is missing, has a bad header, or its size does not match the count.
std::vector<MeshTriangle> readCell(const std::filesystem::path& dir, const GridManifest& manifest,
                                   const GridCell& cell);

}  // namespace gimlod
