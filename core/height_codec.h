// A height block codec for compressed atlases: heights quantized (integers exactly, floats to a
// stated precision), predicted from their decoded neighbours by the 2D Lorenzo predictor
// (left + below - below-left), the residuals zigzagged and split into byte planes, and the whole
// entropy-coded by zstd with its frame checksum, so a corrupt or truncated block is detected.
// Decoding reproduces the quantized heights exactly: errors measured on decoded heights hold for
// what is drawn. Pure C++ over libzstd.
// Based on: Ibarria, Lindstrom, Rossignac, Szymczak, "Out-of-core compression and decompression
// of large n-dimensional scalar fields", Eurographics 2003 (the Lorenzo predictor).
#pragma once

#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace gimlod {

// A block that cannot be decoded: corrupt (checksum), truncated, or not a height block.
class CodecError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// How a block's heights were quantized.
enum class HeightQuantization : uint8_t {
  kInteger = 0,    // every height an integer (SRTM metres): lossless
  kPrecision = 1,  // round(h / precision) * precision: within precision / 2
};

// Encodes side^2 heights (row-major). Heights that are all integers in [-2^30, 2^30] are coded
// losslessly; others are quantized to `precision` (> 0, metres). Throws std::invalid_argument on
// a non-finite height, precision <= 0 for non-integer heights, or a quantized range beyond
// 2^30 steps.
std::vector<uint8_t> encodeHeights(std::span<const float> heights, uint32_t side, double precision);

// Decodes a block made by encodeHeights into out (side^2 heights). Throws CodecError when the
// block is corrupt, truncated, or of another side.
void decodeHeights(std::span<const uint8_t> block, uint32_t side, std::span<float> out);

// The quantization a block used (reads the header only). Throws CodecError on a bad header.
HeightQuantization blockQuantization(std::span<const uint8_t> block);

}  // namespace gimlod
