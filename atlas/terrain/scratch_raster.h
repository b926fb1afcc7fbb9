// The raster a DEM larger than memory is built from, kept on disk while the build runs: heights
// and validity flags in square tiles, each coded losslessly and appended to one file.
// - A tile's heights become 32-bit integers: whole numbers (|h| <= 2^24, no -0) as they are, any
//   other tile's floats as their bits mapped to integers that order as the floats do (so, within
//   a binade, the value in units of the last place). Their 2D Lorenzo residuals (left + below -
//   below-left, modulo 2^32) go as byte planes (those above the largest residual left out) through
//   zstd with its frame checksum (compressBytes, core/block_codec.h). Validity is a flag per
//   tile (all valid, all void) or a plane of bytes.
// - A raw float raster with a validity byte takes 5 bytes per sample; this takes under 1 for the
//   shipped 90 m tile and well under that for a DEM upsampled from a coarser one, so the scratch of
//   a 21.6G-sample DEM fits beside its atlas.
// - Rewriting a tile appends its new version and punches the old one out of the file (where the
//   file system allows), so the disk used stays about that of one version of every tile.
// - Every sample is void with height 0 until written. Reads and writes take any window; tiles
//   are coded and decoded in parallel (TBB). A damaged tile is an InputError naming the scratch
//   file, the DEM and the tile.
// - A raster may be kept (keep) and opened again, read-only, by other processes: a sharded build's
//   prepare step fills it once and every shard reads its windows from it.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <vector>

#include "atlas/terrain/void_fill.h"

namespace gimlod {

class ScratchRaster {
 public:
  // A width x height raster kept in `file` (created; removed when destroyed), in tiles of `tile`
  // samples a side; `dem` names the DEM in messages. Throws InputError when the file cannot be
  // created, std::invalid_argument on an empty raster or a tile side outside 8..4096.
  ScratchRaster(std::filesystem::path file, std::filesystem::path dem, uint64_t width, uint64_t height,
                uint32_t tile = 256);
  // Opens a raster kept by keep(indexFile), read-only; it stays on disk when destroyed. Throws
  // InputError naming the file when the index is missing or damaged or the file is shorter than it
  // says.
  ScratchRaster(std::filesystem::path file, std::filesystem::path dem, const std::filesystem::path& indexFile);
  ~ScratchRaster();
  ScratchRaster(const ScratchRaster&) = delete;
  ScratchRaster& operator=(const ScratchRaster&) = delete;

  // Writes a window's heights (row-major) and validity (nullptr: the samples' validity stays as
  // it was). Throws InputError when the disk is full, std::invalid_argument on a window outside
  // the raster.
  void write(const CellWindow& w, const float* heights, const uint8_t* valid);
  // Reads a window's heights and validity (either may be nullptr).
  void read(const CellWindow& w, float* heights, uint8_t* valid) const;
  // Whether a window holds a void (tiles flagged all valid are not decoded).
  bool hasVoids(const CellWindow& w) const;
  // Flushes the file, writes the tiles' index to indexFile (atomically) and leaves both on disk
  // when the raster is destroyed. Throws InputError naming the file on failure.
  void keep(const std::filesystem::path& indexFile);

  uint32_t tileSide() const { return tile_; }
  // The bytes the file holds now (every tile's latest version), and the most it ever held.
  uint64_t liveBytes() const;
  uint64_t peakBytes() const;
  const std::filesystem::path& path() const { return path_; }

 private:
  struct Tile {
    uint64_t offset = 0;
    uint32_t bytes = 0;    // 0: never written (void, height 0)
    uint8_t validity = 1;  // 0: all valid, 1: all void, 2: mixed
  };
  struct Decoded;
  CellWindow tileWindow(uint64_t t) const;
  std::vector<uint64_t> tilesOf(const CellWindow& w) const;
  // Calls visit(tile, its window, its overlap with w) for every tile w touches, in parallel.
  using TileVisit = std::function<void(uint64_t, const CellWindow&, const CellWindow&)>;
  void forEachTile(const CellWindow& w, const TileVisit& visit) const;
  void decode(uint64_t t, Decoded& out) const;
  void check(const CellWindow& w, const char* what) const;
  [[noreturn]] void fail(const std::string& what) const;

  std::filesystem::path path_, dem_;
  uint64_t width_, height_;
  uint32_t tile_;
  uint64_t tilesX_, tilesY_;
  int fd_ = -1;
  bool kept_ = false;      // left on disk when destroyed
  bool readOnly_ = false;  // opened from an index
  std::vector<Tile> tiles_;
  uint64_t end_ = 0, live_ = 0, peak_ = 0;
  mutable std::mutex mutex_;
};

}  // namespace gimlod
