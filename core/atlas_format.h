// On-disk atlas format shared by every stage: the manifest (atlas.json), chart pyramid files
// stored in blocks, and atomic file writing. Pure C++; no GDAL, OpenMesh, CGAL or GL here.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <glm/vec3.hpp>

#include "core/planet.h"

namespace gimlod {

// Error for bad user input or unreadable files; the message names the file and the problem.
// A message may refer to options through optionRef(): what() names them by their parameter
// names ("chartSize"), and a front end spells them its own way (a command-line flag) with
// message(spell).
class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& message);
  // The message with each option reference spelled as spell(parameter name).
  std::string message(const std::function<std::string(std::string_view)>& spell) const;

 private:
  std::string marked_;  // the message with the option references marked
};

// A reference to the option parameter `name` (e.g. "chartSize") inside an InputError message.
std::string optionRef(std::string_view name);

// What an atlas's charts hold: heights over a terrain grid, or positions sampled from a mesh.
enum class AtlasKind : uint8_t { Heightfield, Geometry };

// The kind's name in the manifest: "heightfield" or "geometry".
const char* atlasKindName(AtlasKind kind);

// Version 2: chart files may be compressed (chart file version 3, AtlasManifest::compression).
// Version 3: version 2 with the chart list in a file of its own (kChartListName), one zstd frame of
// JSON, for an atlas of more than kInlineChartsMax charts: an indoor scan's 80,000 charts took 16 MB
// of manifest, 1.2 MB so. Version 1 atlases (uncompressed chart files) are still read, and still
// written on request.
inline constexpr uint32_t kAtlasFormatVersion = 3;
inline constexpr const char* kManifestName = "atlas.json";
inline constexpr const char* kChartListName = "charts.json.zst";
inline constexpr size_t kInlineChartsMax = 256;

// Chart edges, counter-clockwise in chart (u, v): 0 = bottom (v = 0), 1 = right (u = max),
// 2 = top (v = max), 3 = left (u = 0). The edge parameter runs counter-clockwise.
enum Edge : uint8_t { kEdgeBottom = 0, kEdgeRight = 1, kEdgeTop = 2, kEdgeLeft = 3 };

// Index of sample k (0..chartSize-1) along edge `edge` of a chartSize^2 row-major image, in the
// edge's counter-clockwise parameter direction: bottom (k, 0), right (M, k), top (M - k, M), left
// (0, M - k), M = chartSize - 1. Across a shared edge with reversed = true, sample k here equals
// sample chartSize-1-k of the neighbour's edge. Corner c is sample 0 of edge c.
inline uint32_t edgeSampleIndex(uint32_t chartSize, uint32_t edge, uint32_t k) {
  const uint32_t m = chartSize - 1;
  switch (edge) {
    case kEdgeBottom: return k;
    case kEdgeRight: return k * chartSize + m;
    case kEdgeTop: return m * chartSize + (m - k);
    default: return (m - k) * chartSize;
  }
}

// The chart across one edge of a root. chart < 0: open border (no neighbour).
// reversed: the neighbour's edge parameter runs opposite to ours (always true for two
// consistently oriented charts).
struct RootNeighbour {
  int32_t chart = -1;
  uint8_t edge = 0;
  bool reversed = true;
};

struct Georeference {
  std::string wkt;                       // source spatial reference, may be empty
  std::array<double, 6> geotransform{};  // GDAL geotransform of the source raster
  bool geographic = false;               // source units were degrees
  double centreLatitudeDeg = 0.0;        // latitude used for degree-to-metre conversion
};

struct ChartInfo {
  uint32_t id = 0;
  int32_t gridX = 0, gridY = 0;             // chart position in the terrain chart grid
  std::string file;                         // relative to the atlas directory
  std::string imageryFile;                  // the chart's imagery (AtlasManifest::imagery), or empty
  std::array<RootNeighbour, 4> neighbours;  // indexed by Edge
  // Geometry atlases: the pyramid level of the atlas that the chart file's level 0 is. A chart whose
  // surface its coarser samples already follow within the build's bound keeps only those: its file
  // holds ((chartSize - 1) >> finestLevel) + 1 samples a side, and its level j is the atlas's level
  // finestLevel + j. Node coordinates, seams and stitching stay in the atlas's level-0 units, and
  // the pyramid levels being subsamplings, the shared samples of two charts are the same whatever
  // their finest levels. 0: the whole pyramid (every terrain chart).
  uint32_t finestLevel = 0;
};

// Colour imagery draped over a terrain atlas: per chart, an attribute chart file (colours alone)
// whose sample lattice refines the chart's by 2^scaleLog2 (chart side (chartSize-1) * 2^scaleLog2
// + 1, blocks of blockIntervals * 2^scaleLog2), so a node's imagery page covers exactly its
// geometry page. Imagery level k pairs with pyramid level k. Alpha is 255 where the imagery covers
// the terrain and 0 where it does not.
struct ImageryInfo {
  bool present = false;
  uint32_t scaleLog2 = 0;  // 0..kMaxImageryScaleLog2
  std::string source;      // the raster it came from
  double coverage = 0.0;   // fraction of the terrain's samples the imagery covers
  uint32_t chartSize(uint32_t geometryChartSize) const { return ((geometryChartSize - 1) << scaleLog2) + 1; }
};
inline constexpr uint32_t kMaxImageryScaleLog2 = 2;

// How an atlas's chart files store their blocks (ChartCoding), as the manifest records it.
struct CompressionInfo {
  bool present = false;          // chart files are coded (version 3); the manifest is version 2
  double heightPrecision = 0.0;  // metres: non-integer heights were quantized to it (0: none were)
  double positionStep = 0.0;     // positions' lattice step (geometry atlases)
  // Geometry atlases: how far a position off its chart's border (same units) and a packed
  // normal byte may have been settled from its input (settlePositions, settleNormals); 0: none.
  double positionTolerance = 0.0;
  uint32_t normalTolerance = 0;
};

// The atlas manifest. Heights are in metres after z-scale; horizontal positions of terrain
// sample (gx, gy) are (gx * spacing[0], gy * spacing[1]); gy grows northwards.
struct AtlasManifest {
  uint32_t version = kAtlasFormatVersion;
  AtlasKind kind = AtlasKind::Heightfield;  // "heightfield" (1-channel) or "geometry" on disk
  uint32_t chartSize = 513;                 // samples per chart side, 2^m + 1
  uint32_t blockIntervals = 64;             // block side in intervals (2^t); = max node res R
  uint32_t chartsX = 0, chartsY = 0;
  uint32_t samplesX = 0, samplesY = 0;      // valid DEM extent in global samples
  std::array<double, 2> spacing{1.0, 1.0};  // metres between samples
  double zScale = 1.0;
  std::array<float, 2> heightRange{0.f, 0.f};
  uint64_t voidsFilled = 0;
  std::string voidFillMethod;
  std::string source;
  Georeference georef;
  ImageryInfo imagery;          // terrain imagery (heightfield atlases only)
  PlanetInfo planet;            // a height field on a sphere (heightfield atlases only)
  CompressionInfo compression;  // coded chart files (version 2)
  std::vector<ChartInfo> charts;
  // Hierarchy parameters (log2 values). depth = number of quadtree levels (root = level 0).
  std::string hierarchyFile = "hierarchy.bin";
  uint32_t depth = 5;
  uint32_t maxNodeResLog2 = 6;  // log2(R)
  uint32_t minNodeResLog2 = 2;

  uint32_t intervalsLog2() const;  // log2(chartSize - 1)
  uint32_t pyramidLevels() const { return intervalsLog2() + 1; }
  // Samples a side of chart c's file (ChartInfo::finestLevel).
  uint32_t chartFileSize(uint32_t c) const { return ((chartSize - 1) >> charts[c].finestLevel) + 1; }
};

// Reads and validates dir/atlas.json ("format": "gimlod-atlas", version, chart size and block
// size, chart ids/grid positions, symmetric neighbours, relative chart paths, hierarchy
// parameters), and its chart list file if it has one (version 3). Throws InputError
// "<dir>/atlas.json: <problem>", or naming the chart list file for a problem there.
AtlasManifest readManifest(const std::filesystem::path& dir);
// Writes dir/atlas.json atomically: version 1 without compression, else version 2, or version 3
// with the chart list first written to dir/charts.json.zst (atomically too) when it has more than
// kInlineChartsMax charts. A chart list file a version 1 or 2 manifest leaves unused is removed.
void writeManifest(const std::filesystem::path& dir, const AtlasManifest& m);

// A whole file's bytes. Throws InputError naming the file when it cannot be read.
std::vector<uint8_t> readFileBytes(const std::filesystem::path& path);

// Writes bytes to path.tmp-<pid> and renames it over path. Throws InputError on failure.
void atomicWriteFile(const std::filesystem::path& path, const void* data, size_t bytes);

// The same, piece by piece: the pieces go to path.tmp-<pid>, which commit() flushes and renames
// over path; a writer destroyed uncommitted removes it. Throws InputError naming path. A file
// inside a StagedDirectory of this process is not flushed on its own: the directory's commit
// flushes them all at once.
class AtomicFileWriter {
 public:
  explicit AtomicFileWriter(std::filesystem::path path);
  ~AtomicFileWriter();
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;
  void write(const void* data, size_t bytes);
  // Overwrites bytes already written at `offset` (a header filled in last).
  void writeAt(uint64_t offset, const void* data, size_t bytes);
  void commit();

 private:
  [[noreturn]] void fail(const std::string& what, int err);
  std::filesystem::path path_, tmp_;
  int fd_ = -1;
};

// A sibling temporary directory (".<name>.partial-<pid>-<random>") for building a whole output
// directory; removed unless committed, when it is renamed onto the target (replacing an earlier
// output, which is restored if the rename fails). The target must not exist, be empty, or hold
// `markerFile` (an earlier output of the same kind); anything else is refused. `what` names the
// kind in messages ("atlas", "grid"). Missing parent directories are made. commit() flushes the
// file system the directory is on (syncfs) before the rename, so every file inside is on the disk
// when the output appears. Throws InputError naming the target.
class StagedDirectory {
 public:
  StagedDirectory(const std::filesystem::path& target, const std::string& markerFile, const std::string& what);
  ~StagedDirectory();
  StagedDirectory(const StagedDirectory&) = delete;
  StagedDirectory& operator=(const StagedDirectory&) = delete;
  const std::filesystem::path& path() const { return path_; }
  void commit();

 private:
  std::filesystem::path target_, path_;
  std::string what_;
  bool committed_ = false;
};

// Normal stored as 4 x uint8 (n * 127.5 + 127.5, w = 255).
using PackedNormal = std::array<uint8_t, 4>;
// Packs a unit normal (components clamped to [-1, 1], rounded to nearest). Deterministic.
PackedNormal packNormal(float x, float y, float z);
// Inverse of packNormal (not renormalised): c / 127.5 - 1.
std::array<float, 3> unpackNormal(const PackedNormal& n);

// True if n = 2^m + 1 for some m >= 1 (3, 5, 9, ..., 65537).
bool isChartSizeValid(uint32_t n);

// Block layout of one pyramid level: the level has (chartSize-1)>>level intervals per side; it is
// cut into blocksPerSide^2 blocks of blockSamples^2 samples sharing one row/column with the next.
struct LevelLayout {
  uint32_t samples = 0;        // (M >> level) + 1
  uint32_t blocksPerSide = 0;  // max(1, (M >> level) / B)
  uint32_t blockSamples = 0;   // min(B, M >> level) + 1
};
// Layout of pyramid level `level`; throws std::logic_error on an invalid chartSize, blockIntervals
// or level.
LevelLayout levelLayout(uint32_t chartSize, uint32_t blockIntervals, uint32_t level);
// The finest pyramid level that one block holds whole: log2((chartSize - 1) / blockIntervals).
// Every coarser level is a subsampling of it (every 2^j-th sample), so a chart file with flag 8
// stores the levels down to this one only (writeChartFile).
uint32_t firstSingleBlockLevel(uint32_t chartSize, uint32_t blockIntervals);

// The sample channels a chart file can hold.
enum ChartChannel : uint32_t {
  kChannelHeights = 0,    // float32: height field (terrain)
  kChannelNormals = 1,    // PackedNormal
  kChannelPositions = 2,  // 3 x float32: geometry image (mesh atlas)
  kChannelColours = 3,    // RGBA8
  kChannelCount = 4
};
using PackedColour = std::array<uint8_t, 4>;

// Where a terrain chart lies on its DEM's sample lattice. A height field's normal at a sample of
// pyramid level k is the central difference of the heights 2^k samples away on either side, the
// neighbours clamped to the DEM (one-sided differences at its edges, flat beyond them), divided by
// the distance actually spanned. Where the columns circle a planet (column maxX is column 0), the
// differences cross the antimeridian as any other column: the neighbours wrap, and every span is
// whole. It depends only on global coordinates, so charts agree on shared sides (the antimeridian's
// included), and a compressed atlas derives the normals from its decoded heights instead of storing
// them.
struct HeightFieldFrame {
  int64_t originX = 0, originY = 0;         // global sample of the chart's (0, 0)
  int64_t maxX = 0, maxY = 0;               // the DEM's last column and row
  std::array<double, 2> spacing{1.0, 1.0};  // metres between samples
  bool wrapX = false;                       // the columns circle a planet (PlanetInfo::wrapColumns = maxX)
};

// The normals of a geometry image's samples off its border, from its positions (x, y, z
// interleaved, side^2, row-major): the cross product of the differences along u and along v (the
// orientation of the image's counter-clockwise triangles), packed. The differences are the
// central ones over 2 and over 4 intervals summed where the image holds them (2 samples or more
// from its border), else over 2; where the cross product vanishes, of one-sided differences;
// (0, 0, 1) where every one does. The border samples of out are left as they are.
void geometryImageNormals(const float* xyz, uint32_t side, PackedNormal* out);

// A window of one pyramid level of a chart: its samples [u0, u0 + w) x [v0, v0 + h) of level `level`.
struct LevelWindow {
  uint32_t level = 0;
  uint32_t u0 = 0, v0 = 0;
  uint32_t w = 0, h = 0;
};

// The normals of the window `window` of the chart at `frame`, from its heights with a one-sample
// ring: heights[0] is the height of (u0, v0), rows are `stride` floats apart, and the ring lies at
// -1 and at w (h). out: w * h row-major.
void heightFieldNormals(const float* heights, size_t stride, const LevelWindow& window, const HeightFieldFrame& frame,
                        PackedNormal* out);

// One chart's pyramid in memory: level k is a (samples_k)^2 row-major image (row = v). A
// height-field chart has heights and normals; a geometry chart has positions and normals, and
// colours when the source had them. Absent channels are empty.
struct ChartPyramid {
  std::vector<std::vector<float>> heights;         // [level][v * samples + u]
  std::vector<std::vector<PackedNormal>> normals;  // [level][v * samples + u]
  std::vector<std::vector<glm::vec3>> positions;   // [level][v * samples + u]
  std::vector<std::vector<PackedColour>> colours;  // [level][v * samples + u]
  // Height-field charts for a compressed file (writeChartFile): each level's heights with a
  // one-sample ring from the neighbouring lattice ((samples + 2)^2, row-major), and where the chart
  // lies. The file then stores these heights and derives the normals from them on reading.
  std::vector<std::vector<float>> ringHeights;
  std::optional<HeightFieldFrame> frame;
};

// How writeChartFile stores blocks. Uncompressed: raw samples (chart file version 1 or 2, below).
// Compressed (version 3): every block of every channel is coded on its own by core/block_codec.h
// (heights: integers losslessly, others quantized to heightPrecision; positions quantized to
// positionStep on one lattice through the origin; normals and colours losslessly) and carries its
// own checksum. Values already quantized to the same step decode to themselves, so a caller that
// quantizes before measuring (quantizeToStep) measures exactly what is drawn.
struct ChartCoding {
  bool compressed = false;
  double heightPrecision = 0.01;  // metres
  double positionStep = 0.0;      // required (> 0) for compressed positions
  // Geometry charts, compressed: samples off a chart's border are settled on the lattice within
  // these tolerances before they are coded (core/block_codec.h settlePositions, settleNormals).
  double positionTolerance = 0.0;  // same units as positionStep
  uint32_t normalTolerance = 0;    // packed normal steps
  // Geometry charts, compressed: store the normals of block borders only and derive the others
  // from the decoded positions on reading (geometryImageNormals; flag 2 of version 3).
  bool deriveGeometryNormals = false;
};

// Whether a geometry pyramid's levels past the first one-block level (firstSingleBlockLevel) are
// every channel's subsamplings of it, so that a compressed chart file need not store them.
bool coarseLevelsSubsampled(const ChartPyramid& pyramid, uint32_t chartSize, uint32_t blockIntervals);

// Writes a chart file. A height-field pyramid (heights + normals) is written uncompressed in
// version 1; a pyramid with positions or colours, or colours alone (an attribute chart: terrain
// imagery), in version 2: the same, but the header adds u32 channelMask
// (1 << ChartChannel) after the level count, each directory entry holds one u64 offset per
// present channel (in ChartChannel order), and each block stores its channels in that order.
// Version 1 (little-endian): magic "GLMC", u32 version (1), u32 chartSize,
// u32 blockIntervals, u32 levels; a directory, for each level and each block by rows
// (by * blocksPerSide + bx), of u64 heightOffset and u64 normalOffset; then per block its
// blockSamples^2 float32 heights followed by its blockSamples^2 PackedNormal, row-major. Block
// (bx, by) of level k holds samples u in [bx*B, bx*B+B], v in [by*B, by*B+B] with
// B = min(blockIntervals, M >> k): neighbouring blocks share one row/column.
// Version 3 (coding.compressed): the version 2 header with version 3, then u32 flags; with flag 1
// (a height-field pyramid with ringHeights and frame) the normals are derived, not stored: the
// header adds the frame (i64 originX, originY, maxX, maxY, f64 spacing x, y), and each heights
// block holds its (blockSamples + 2)^2 heights with the ring; with flag 2 (a geometry pyramid,
// coding.deriveGeometryNormals) each normals block holds its border's normals only
// (encodeBorderNormals) and the reader derives the others from the block's positions
// (geometryImageNormals). Each directory entry holds, per stored channel, u64 offset and u32
// byte count of the block's code. With flag 8 (a compressed geometry pyramid whose coarse levels
// are subsamplings: coarseLevelsSubsampled) the file stores levels 0 to firstSingleBlockLevel
// only, and the reader takes each coarser level's samples from that level's block (normals of
// flag 2: their border, the others derived from the level's positions as at any level).
// Written block by block in level order (ChartFileWriter) and renamed into place. Returns bytes
// written. Throws std::invalid_argument on a malformed pyramid or one the coding cannot take,
// InputError if the file cannot be written.
uint64_t writeChartFile(const std::filesystem::path& path, const ChartPyramid& pyramid, uint32_t chartSize,
                        uint32_t blockIntervals, const ChartCoding& coding = {});

// One channel of one block as a writer takes it: element (0, 0) of the block (of its ring, for the
// ring heights of a height field whose normals are derived), rows `stride` elements apart.
struct BlockChannel {
  const void* data = nullptr;
  size_t stride = 0;
};
using BlockData = std::array<BlockChannel, kChannelCount>;

// What a chart file holds: a chart of chartSize samples a side in blocks of blockIntervals, its
// first `levels` pyramid levels, and the channels of channelMask (bits 1 << ChartChannel).
struct ChartFileShape {
  uint32_t chartSize = 0;
  uint32_t blockIntervals = 0;
  uint32_t levels = 0;
  uint32_t channelMask = 0;
  // Compressed geometry only: the levels past firstSingleBlockLevel are not stored (flag 8); the
  // writer takes blocks of the stored levels only.
  bool subsampledLevels = false;
};

// A chart file written a block at a time, in any order and from any thread, so that a chart's
// size does not bound the memory that writes it: the header and the directory are reserved
// first, each block is coded (or made little-endian) by the calling thread and appended, and
// commit() fills the directory in and renames the file into place (AtomicFileWriter). Written in
// level order (level, then rows of blocks), the file is byte for byte what writeChartFile made
// when it built whole files in memory. shape.channelMask: as writeChartFile derives it (heights and
// normals, positions and normals with or without colours, or colours alone); frame: a compressed
// height field's, whose normals are then derived (its blocks give ring heights, no normals).
class ChartFileWriter {
 public:
  // Throws std::invalid_argument for a bad size, level count, mask or coding; InputError if the
  // file cannot be created.
  ChartFileWriter(std::filesystem::path path, const ChartFileShape& shape, const ChartCoding& coding,
                  std::optional<HeightFieldFrame> frame = {});
  // Carries on the partial chart file `partial` (commitPartial's, of the same shape and coding):
  // its blocks are copied into `path` in their order, and the writer takes the others. Throws
  // InputError naming `partial` when it is not such a file.
  ChartFileWriter(std::filesystem::path path, const ChartFileShape& shape, const ChartCoding& coding,
                  const std::filesystem::path& partial);
  ~ChartFileWriter();
  ChartFileWriter(const ChartFileWriter&) = delete;
  ChartFileWriter& operator=(const ChartFileWriter&) = delete;
  // A block coded as the file stores it, not yet placed.
  struct CodedBlock {
    uint32_t level = 0, bx = 0, by = 0;
    std::array<std::vector<uint8_t>, kChannelCount> bytes;  // per stored channel
  };
  // Block (bx, by) of `level`, from a pointer for each channel the file stores, coded. Thread-safe.
  CodedBlock code(uint32_t level, uint32_t bx, uint32_t by, const BlockData& data) const;
  // Appends a coded block. Thread-safe; a block is written once (std::logic_error otherwise). The
  // file's bytes follow the order of the calls.
  void append(const CodedBlock& block);
  void writeBlock(uint32_t level, uint32_t bx, uint32_t by, const BlockData& data) {
    append(code(level, bx, by, data));
  }
  // Throws std::logic_error when a block is missing. Returns the file's bytes.
  uint64_t commit();
  // Writes the file with the blocks appended so far (a partial chart file: the directory holds
  // their entries alone), for a writer of another process to carry on; this writer takes no more
  // blocks. Returns the file's bytes.
  uint64_t commitPartial();
  const std::filesystem::path& path() const { return path_; }
  uint32_t chartSize() const;
  uint32_t blockIntervals() const;

 private:
  struct Impl;
  std::filesystem::path path_;
  std::unique_ptr<Impl> impl_;
};

// Random access to one chart file's blocks; reads only the requested block. Thread-safe.
class ChartFileReader {
 public:
  explicit ChartFileReader(const std::filesystem::path& path);  // throws InputError
  uint32_t chartSize() const { return chartSize_; }
  uint32_t blockIntervals() const { return blockIntervals_; }
  uint32_t levels() const { return levels_; }
  // Levels with blocks in the file: levels() unless the coarser ones are subsampled (flag 8).
  uint32_t storedLevels() const { return storedLevels_; }
  // Reads the window of level `level` with origin (u0, v0) and side n+1 samples (n intervals),
  // which must lie inside one block. Output row-major (n+1)^2.
  void readHeights(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n, float* out) const;
  void readNormals(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n, PackedNormal* out) const;
  // Reads a whole level (all blocks).
  std::vector<float> readLevelHeights(uint32_t level) const;
  // The (n+1)^2 heights of level `level` from (u0, v0), a window of whole blocks (u0, v0 and n
  // multiples of the level's block intervals), row-major.
  std::vector<float> readHeightsWindow(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n) const;
  std::vector<PackedNormal> readLevelNormals(uint32_t level) const;
  // Geometry charts (version 2). Throw std::logic_error when the file lacks the channel.
  void readPositions(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n, glm::vec3* out) const;
  void readColours(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n, PackedColour* out) const;
  std::vector<glm::vec3> readLevelPositions(uint32_t level) const;
  std::vector<PackedColour> readLevelColours(uint32_t level) const;
  uint32_t channelMask() const { return channelMask_; }  // bits 1 << ChartChannel
  bool hasChannel(ChartChannel c) const { return (channelMask_ >> c) & 1u; }
  bool compressed() const { return compressed_; }                               // version 3: blocks decoded on read
  bool derivedNormals() const { return frame_.has_value() || borderNormals_; }  // from heights or positions
  const std::filesystem::path& path() const { return path_; }
  // Version 3: the code of block (bx, by) of level `level`'s channel c as stored, undecoded (for
  // inspection and benchmarks; the read functions decode it). Throws std::logic_error on an
  // uncompressed file, a channel it lacks or a block it does not have (a level past
  // storedLevels() has none); InputError if the read fails.
  std::vector<uint8_t> readCodedBlock(ChartChannel c, uint32_t level, uint32_t bx, uint32_t by) const;

 private:
  struct BlockEntry {  // per ChartChannel
    std::array<uint64_t, kChannelCount> offset{};
    std::array<uint32_t, kChannelCount> bytes{};  // coded bytes (version 3)
  };
  const BlockEntry& block(uint32_t level, uint32_t bx, uint32_t by) const;
  // Block holding the window [u0, u0+n] x [v0, v0+n]; throws std::logic_error if none does.
  void locateWindow(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n, uint32_t& bx, uint32_t& by) const;
  // Reads a window of one block: `rows` rows of `rowBytes` bytes, `pitch` bytes apart from byte
  // `first` of the file, into out one after the other; caller holds no lock.
  void readWindow(uint64_t first, uint64_t pitch, size_t rowBytes, uint32_t rows, void* out) const;
  std::filesystem::path path_;
  // Reads a window of one channel into out, in the channel's elements (float, PackedNormal, 3
  // floats, PackedColour).
  void readChannel(ChartChannel c, uint32_t level, uint32_t u0, uint32_t v0, uint32_t n, void* out) const;
  uint32_t chartSize_ = 0, blockIntervals_ = 0, levels_ = 0, storedLevels_ = 0;
  uint32_t channelMask_ = 0;
  bool compressed_ = false;
  std::optional<HeightFieldFrame> frame_;  // normals derived from the heights (version 3)
  bool borderNormals_ = false;             // geometry: normals stored on block borders, the rest derived
  uint64_t serial_ = 0;                    // tells this reader's decoded blocks from another's
  // Version 3: the whole block (bx, by) of stored channel c, decoded (side^2 elements, side the
  // block's samples, plus 2 for ring heights); the thread's buffer, valid until its next call.
  const std::vector<uint8_t>& decodeBlock(ChartChannel c, uint32_t level, uint32_t bx, uint32_t by) const;
  // Version 3: block (bx, by) of level `level`'s stored channel c decoded into out as coded
  // (normals of flag 2: their border alone). Throws InputError naming the file and the block.
  void decodeCode(ChartChannel c, uint32_t level, uint32_t bx, uint32_t by, std::vector<uint8_t>& out) const;
  // Version 3 with flag 8: the last stored level's block of channel c decoded as coded (the
  // thread's, kept for this reader's next call).
  const std::vector<uint8_t>& storedSource(ChartChannel c) const;
  // Version 3 with flag 8: level `level` (past the stored ones) of channel c, every 2^j-th sample
  // of the last stored level's block, into out.
  void subsampleStored(ChartChannel c, uint32_t level, std::vector<uint8_t>& out) const;
  // Version 3: the stored code of block (bx, by) of channel c into `code`.
  void readCode(ChartChannel c, uint32_t level, uint32_t bx, uint32_t by, std::vector<uint8_t>& code) const;
  std::vector<std::vector<BlockEntry>> directory_;  // [level][by * blocksPerSide + bx]
  mutable std::mutex mutex_;
  mutable std::ifstream file_;
};

}  // namespace gimlod
