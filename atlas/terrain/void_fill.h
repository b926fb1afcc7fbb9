// Pull-push void filling of a DEM, over windows of its cells, so that a raster too large for
// memory is filled window by window with exactly the values the whole-raster fill gives.
// - Pull: level l+1 has ceil(n/2) cells per axis; cell i is centred between level-l cells 2i and
//   2i+1 and averages the valid cells among 2i-1 .. 2i+2 with the separable weights [1 3 3 1]. A
//   coarse cell is valid iff any tap is. Pulling stops at the first level without voids (L).
// - Push: from level L down, every void cell at level l takes the bilinear interpolation of level
//   l+1 at its centre (centres tracked per axis in level-0 coordinates; beyond the outermost coarse
//   centres the value is held constant), then 4 relaxation sweeps move the cells just filled
//   towards the mean of their 4 neighbours.
// - The relaxation is Gauss-Seidel (fixed raster order) on the coarse levels at and above
//   kWindowedFillLevels, which are small and filled whole in memory, and Jacobi on the finer ones:
//   there a cell's value depends only on cells a bounded distance away, so a window with that
//   margin computes it exactly.
// Every filled value is a convex combination of valid samples (no overshoot); work is O(N).
// Based on: Gortler, Grzeszczuk, Szeliski, Cohen, "The Lumigraph", SIGGRAPH 1996 (pull-push).
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

namespace gimlod {

// Levels below this are filled window by window (Jacobi relaxation); those at and above it whole.
inline constexpr uint32_t kWindowedFillLevels = 4;

// A window of cells [x0, x1) x [y0, y1) of one pyramid level, in that level's global indices.
struct CellWindow {
  int64_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  int64_t width() const { return x1 - x0; }
  int64_t height() const { return y1 - y0; }
  bool empty() const { return x1 <= x0 || y1 <= y0; }
  size_t cells() const { return empty() ? 0 : size_t(width()) * size_t(height()); }
};

// Fills the voids (mask == true) of a width x height raster in place; returns the number filled.
// Throws std::invalid_argument on size mismatch or when no sample is valid.
uint64_t fillVoids(std::vector<float>& heights, const std::vector<bool>& voidMask, uint32_t width, uint32_t height);

// The same fill, window by window, for a raster that does not fit in memory.
// - read(window, heights, valid): the level-0 samples of a window, row-major (valid 0 at voids).
// - write(core, heights): the filled samples of a core window (valid samples unchanged); cores
//   tile the raster, and write is called only for cores with voids.
// - lo, hi: the range of the raster's valid samples (fills are clamped to it, as fillVoids does).
// - windowSamples: about the largest window read at once (samples); it bounds the memory used,
//   with the coarse levels (about width * height / 4^kWindowedFillLevels cells).
// - hasVoids(window): whether a level-0 window holds a void (cores without are skipped).
// Filled values are bit-identical to fillVoids'. Throws std::invalid_argument when no sample is
// valid.
struct WindowedFill {
  std::function<void(const CellWindow&, float* heights, uint8_t* valid)> read;
  std::function<void(const CellWindow&, const float* heights)> write;
  std::function<bool(const CellWindow&)> hasVoids;
};
void fillVoidsWindowed(uint32_t width, uint32_t height, float lo, float hi, const WindowedFill& io,
                       uint64_t windowSamples);

}  // namespace gimlod
