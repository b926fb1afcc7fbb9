// Block codecs for compressed atlases: one chart block of one channel in, a self-checking byte
// string out. Every codec predicts each sample from its decoded neighbours by the 2D Lorenzo
// predictor (left + below - below-left; a block's first sample is stored as it is), or positions
// and normals by interpolation from coarse to fine where that codes smaller, maps the
// residuals to small unsigned values, splits them into byte planes and entropy-codes the whole with
// zstd and its frame checksum, so a corrupt or truncated block is detected, never decoded to wrong
// samples.
// - Heights and positions are quantized first (integers exactly, else to a stated step), and
//   decoding reproduces the quantized values exactly: errors measured on decoded samples hold for
//   what is drawn, and samples that were equal before coding (shared seams) stay equal.
// - Normals and colours are 8-bit and coded losslessly; a normal's z is predicted from its x and y
//   (unit length), so it costs almost nothing.
// Pure C++ over libzstd.
// Based on: Ibarria, Lindstrom, Rossignac, Szymczak, "Out-of-core compression and decompression
// of large n-dimensional scalar fields", Eurographics 2003 (the Lorenzo predictor).
#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace gimlod {

// A block that cannot be decoded: corrupt (checksum), truncated, or of another kind or side.
class CodecError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// How a block's heights were quantized.
enum class HeightQuantization : uint8_t {
  kInteger = 0,    // every height an integer (SRTM metres): lossless
  kPrecision = 1,  // round(h / precision) * precision: within precision / 2
};

// The value a height or coordinate decodes to after quantization to `step` (> 0):
// float(round(v / step) * step). Quantizing a quantized value again gives it back, so an atlas
// quantized before it is coded decodes to exactly what was measured.
float quantizeToStep(float v, double step);

// Encodes side^2 heights (row-major). Heights that are all integers in [-2^28, 2^28] are coded
// losslessly; others are quantized to `precision` (> 0, metres). Throws std::invalid_argument on
// a non-finite height, precision <= 0 for non-integer heights, or a quantized range beyond
// 2^28 steps.
std::vector<uint8_t> encodeHeights(std::span<const float> heights, uint32_t side, double precision);

// Decodes a block made by encodeHeights into out (side^2 heights). Throws CodecError when the
// block is corrupt, truncated, or of another side.
void decodeHeights(std::span<const uint8_t> block, uint32_t side, std::span<float> out);

// The quantization a block used (reads the header only). Throws CodecError on a bad header.
HeightQuantization blockQuantization(std::span<const uint8_t> block);

// Encodes side^2 positions (x, y, z interleaved, row-major), each coordinate quantized to `step`
// (> 0) on one lattice through the origin. Throws std::invalid_argument on a non-finite
// coordinate, step <= 0, or a coordinate beyond 2^28 steps.
// Planar squares: with chartBorderSides >= 0 (the block's edges on its chart's border, bits
// kChartBorder*), the encoder also finds the squares of the block (its whole side, its halves, ...
// down to 2 intervals, on the grid of their own size) whose samples all lie where the render
// grids' two triangles of the square's corners put them (planarSquareSample), the largest first.
// It codes their corners and none of their other samples, and the decoder interpolates those, so
// the block still decodes to exactly its samples; samples on a chart-border edge are always coded.
// That code is kept where it is smaller than every sample's. Every sample's residuals are coded
// in row order (Lorenzo) or, for a side of 2^k + 1, in settlePositions' interpolation order,
// whichever is smaller.
// A writer that moves samples there (geometryPyramid) stores fewer. -1: every sample coded.
// interpolated false: the row order's and the planar squares' codes only (flags 1 and 2, as
// readers before flag 4 decode).
std::vector<uint8_t> encodePositions(std::span<const float> xyz, uint32_t side, double step, int chartBorderSides = -1,
                                     bool interpolated = true);
inline constexpr uint8_t kChartBorderBottom = 1, kChartBorderRight = 2, kChartBorderTop = 4, kChartBorderLeft = 8;
// Where a planar square of s intervals (a power of two) puts its sample (x0 + dx, y0 + dy),
// 0 <= dx, dy <= s, from its corners' lattice points q00 (x0, y0), q10 (x0 + s, y0), q01
// (x0, y0 + s), q11 (x0 + s, y0 + s), per coordinate: on the two triangles split along
// (0,0)-(1,1), rounded half up, in exact integer arithmetic. The two squares of an edge agree on
// it, and a square's subsampling puts its samples where the half-size square would.
inline int32_t planarSquareSample(int64_t q00, int64_t q10, int64_t q01, int64_t q11, uint32_t s, uint32_t dx,
                                  uint32_t dy) {
  const int64_t si = s;
  const int64_t v = dx >= dy ? si * q00 + int64_t(dx) * (q10 - q00) + int64_t(dy) * (q11 - q10)
                             : si * q00 + int64_t(dy) * (q01 - q00) + int64_t(dx) * (q11 - q01);
  return int32_t((v + si / 2) >> std::countr_zero(s));  // floor((v + s / 2) / s): s a power of two
}
// Decodes a block made by encodePositions into out (3 side^2 floats). Throws CodecError.
void decodePositions(std::span<const uint8_t> block, uint32_t side, std::span<float> out);

// Error-bounded settling: picks the values a lossless coding codes cheaply. Quantizing each
// coordinate to its nearest lattice point leaves the residuals of a smooth surface spread over
// many values; choosing instead, for each sample off the image's border in the interpolation
// order (the corners, then for each spacing h from (side - 1) / 2 down to 1 the midpoints of the
// rows' intervals of 2h, of the columns', and the centres), the lattice point its prediction (the
// mean of its two neighbours at h, a centre's along the diagonal (0,0)-(1,1), from the samples
// already chosen) reaches in whole multiples of S steps, with S as large as the sample's tolerance
// allows, makes most residuals 0 where the surface is smooth, at every pyramid level that
// subsamples the image and in every block of 2^j + 1 samples a side (encodePositions' interpolated
// code). The coding itself stays lossless: readers decode exactly the settled values, and
// whatever is measured on them (errors, distances) holds for what is drawn.
// - Border samples (first and last row and column) go to their nearest lattice point, as
//   quantizeToStep puts them, so sides shared with other images stay bit-identical.
// - Each other sample moves at most min(tolerance, d / 4) from its input (Euclidean), d its
//   distance to the nearest other sample of its 5x5 grid window, so close samples are not merged;
//   a sample whose choice would coincide with a border sample or one settled before it, anywhere
//   in the image, or (a centre, the last corner of the four texels of spacing h round it) close a
//   triangle of no area (three samples on one line) in them, takes its nearest lattice point, or
//   else the free lattice point closest to its input within 3 steps of that (per coordinate).
// side^2 positions (x, y, z interleaved, row-major) in, side 2^k + 1 (or at most 2: every sample
// on the border), settled positions out (the input of encodePositions). tolerance 0: every sample
// to its nearest lattice point. Throws std::invalid_argument as encodePositions does, on another
// side, or on a negative tolerance.
std::vector<float> settlePositions(std::span<const float> xyz, uint32_t side, double step, double tolerance);

// Encodes side^2 packed unit normals (x, y, z bytes, n * 127.5 + 127.5; the fourth byte 255)
// losslessly. Two predictions are tried and the smaller code kept: the Lorenzo predictor, and,
// where side is 2^k + 1, interpolation in coarse-to-fine order (the corners, then for each spacing
// h from (side - 1) / 2 down to 1 the midpoints of the rows' intervals of 2h, the columns', and the
// centres, each from the rounded mean of its two or four neighbours at h). Either way z is
// predicted from x and y (unit length). decodeNormals reads both. Throws std::invalid_argument if
// a fourth byte is not 255.
std::vector<uint8_t> encodeNormals(std::span<const std::array<uint8_t, 4>> normals, uint32_t side);
void decodeNormals(std::span<const uint8_t> block, uint32_t side, std::span<std::array<uint8_t, 4>> out);

// Error-bounded settling of side^2 packed unit normals (the input of encodeNormals), in place,
// block by block (blocks of min(blockIntervals, side - 1) intervals, as a chart file stores them):
// in the interpolation order, each byte of a sample off its block's border moves towards its
// prediction in multiples of 2 tolerance + 1, by at most `tolerance` packed steps (1/127.5), z
// towards the unit length predicted from x and y. Smooth normals then interpolate to 0 residuals.
// Samples on block borders (which neighbouring blocks and charts share) never move. tolerance 0
// changes nothing. Throws std::invalid_argument unless side is 2^k + 1, blockIntervals a power
// of two and tolerance at most 127.
void settleNormals(std::span<std::array<uint8_t, 4>> normals, uint32_t side, uint32_t tolerance,
                   uint32_t blockIntervals);

// Geometry images whose normals are derived from their positions store only the normals of a
// block's border (4 (side - 1) samples, which the neighbouring block shares), coded losslessly
// in ring order: the first row left to right, the last column upwards, the last row right to
// left, the first column downwards. side >= 2. encodeBorderNormals reads the border of side^2
// packed normals; decodeBorderNormals writes it and leaves the other samples as they are.
std::vector<uint8_t> encodeBorderNormals(std::span<const std::array<uint8_t, 4>> normals, uint32_t side);
void decodeBorderNormals(std::span<const uint8_t> block, uint32_t side, std::span<std::array<uint8_t, 4>> out);

// Encodes side^2 RGBA8 colours losslessly.
std::vector<uint8_t> encodeColours(std::span<const std::array<uint8_t, 4>> colours, uint32_t side);
void decodeColours(std::span<const uint8_t> block, uint32_t side, std::span<std::array<uint8_t, 4>> out);

// A whole byte string (a file's body) as one self-checking zstd frame (at the blocks' level), and
// back. decompressBytes throws CodecError on a corrupt or truncated frame, or one that would
// decode to more than maxBytes.
std::vector<uint8_t> compressBytes(std::span<const uint8_t> raw);
// The same frame made piece by piece, for a body too large to hold twice: `total` bytes are added
// in pieces, and the coded bytes go to `sink` as they are made (decompressBytes reads the whole).
// finish() throws std::logic_error unless exactly `total` bytes were added.
class BytesCompressor {
 public:
  BytesCompressor(uint64_t total, std::function<void(const uint8_t*, size_t)> sink);
  ~BytesCompressor();
  BytesCompressor(const BytesCompressor&) = delete;
  BytesCompressor& operator=(const BytesCompressor&) = delete;
  void add(std::span<const uint8_t> piece);
  void finish();

 private:
  void drive(std::span<const uint8_t> piece, bool end);
  struct State;
  std::unique_ptr<State> state_;
};
std::vector<uint8_t> decompressBytes(std::span<const uint8_t> coded, size_t maxBytes);
// A plain zstd frame (with its content size and checksum, no magic of ours: the zstd tool reads
// it) at zstd level `level`, and back. decompressFrame throws CodecError as decompressBytes does.
std::vector<uint8_t> compressFrame(std::span<const uint8_t> raw, int level);
std::vector<uint8_t> decompressFrame(std::span<const uint8_t> coded, size_t maxBytes);

}  // namespace gimlod
