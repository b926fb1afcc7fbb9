#include "core/height_codec.h"

#include <cmath>
#include <cstring>
#include <memory>

#include <zstd.h>

namespace gimlod {
namespace {

constexpr char kMagic[4] = {'G', 'H', 'B', '1'};
constexpr size_t kHeaderBytes = 16;       // inside the frame: quantization, planes, side, precision
constexpr int64_t kMaxSteps = int64_t{1} << 28;  // |quantized| bound: residuals fit 31 bits
constexpr int kLevel = 3;

struct CCtxFree { void operator()(ZSTD_CCtx* c) const { ZSTD_freeCCtx(c); } };
struct DCtxFree { void operator()(ZSTD_DCtx* c) const { ZSTD_freeDCtx(c); } };

ZSTD_CCtx* compressor() {
  thread_local std::unique_ptr<ZSTD_CCtx, CCtxFree> c([] {
    ZSTD_CCtx* x = ZSTD_createCCtx();
    ZSTD_CCtx_setParameter(x, ZSTD_c_compressionLevel, kLevel);
    ZSTD_CCtx_setParameter(x, ZSTD_c_checksumFlag, 1);
    return x;
  }());
  return c.get();
}

ZSTD_DCtx* decompressor() {
  thread_local std::unique_ptr<ZSTD_DCtx, DCtxFree> d(ZSTD_createDCtx());
  return d.get();
}

inline uint32_t zigzag(int32_t r) { return (uint32_t(r) << 1) ^ uint32_t(r >> 31); }
inline int32_t unzigzag(uint32_t z) { return int32_t(z >> 1) ^ -int32_t(z & 1); }

// The Lorenzo prediction of sample (x, y) from its decoded neighbours (left, below, below-left);
// the first row and column use their one neighbour, the first sample 0.
inline int64_t predict(const int32_t* q, uint32_t side, uint32_t x, uint32_t y) {
  const size_t i = size_t(y) * side + x;
  if (x > 0 && y > 0) return int64_t(q[i - 1]) + q[i - side] - q[i - side - 1];
  if (x > 0) return q[i - 1];
  if (y > 0) return q[i - side];
  return 0;
}

}  // namespace

std::vector<uint8_t> encodeHeights(std::span<const float> heights, uint32_t side, double precision) {
  const size_t n = size_t(side) * side;
  if (side == 0 || heights.size() != n) throw std::invalid_argument("encodeHeights: expected side^2 heights");
  bool integer = true;
  for (float h : heights) {
    if (!std::isfinite(h)) throw std::invalid_argument("encodeHeights: non-finite height");
    integer = integer && h == std::nearbyint(h) && std::abs(h) <= float(kMaxSteps);
  }
  const HeightQuantization mode = integer ? HeightQuantization::kInteger : HeightQuantization::kPrecision;
  if (!integer && !(precision > 0.0 && std::isfinite(precision)))
    throw std::invalid_argument("encodeHeights: non-integer heights need a precision > 0");
  const double step = integer ? 1.0 : precision;
  std::vector<int32_t> q(n);
  for (size_t i = 0; i < n; ++i) {
    const double v = std::nearbyint(double(heights[i]) / step);
    if (std::abs(v) > double(kMaxSteps))
      throw std::invalid_argument("encodeHeights: heights span more than 2^28 steps of the precision");
    q[i] = int32_t(v);
  }
  // Residuals, zigzagged, as byte planes (low bytes first); planes above the highest non-zero
  // byte are left out.
  std::vector<uint32_t> z(n);
  uint32_t all = 0;
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) {
      const size_t i = size_t(y) * side + x;
      z[i] = zigzag(int32_t(int64_t(q[i]) - predict(q.data(), side, x, y)));
      all |= z[i];
    }
  uint8_t planes = 1;
  while (planes < 4 && (all >> (8 * planes)) != 0) ++planes;
  std::vector<uint8_t> raw(kHeaderBytes + size_t(planes) * n);
  raw[0] = uint8_t(mode);
  raw[1] = planes;
  std::memcpy(raw.data() + 4, &side, 4);
  std::memcpy(raw.data() + 8, &step, 8);
  for (uint8_t p = 0; p < planes; ++p) {
    uint8_t* plane = raw.data() + kHeaderBytes + size_t(p) * n;
    for (size_t i = 0; i < n; ++i) plane[i] = uint8_t(z[i] >> (8 * p));
  }
  std::vector<uint8_t> out(sizeof kMagic + ZSTD_compressBound(raw.size()));
  std::memcpy(out.data(), kMagic, sizeof kMagic);
  const size_t written =
      ZSTD_compress2(compressor(), out.data() + sizeof kMagic, out.size() - sizeof kMagic, raw.data(), raw.size());
  if (ZSTD_isError(written)) throw std::runtime_error(std::string("encodeHeights: zstd: ") + ZSTD_getErrorName(written));
  out.resize(sizeof kMagic + written);
  return out;
}

HeightQuantization blockQuantization(std::span<const uint8_t> block) {
  if (block.size() < sizeof kMagic || std::memcmp(block.data(), kMagic, sizeof kMagic) != 0)
    throw CodecError("not a height block (bad magic)");
  // The header is the frame's first bytes: decode just those (the checksum is the decoder's).
  ZSTD_DCtx* d = decompressor();
  ZSTD_DCtx_reset(d, ZSTD_reset_session_only);
  uint8_t head[kHeaderBytes];
  ZSTD_outBuffer out{head, sizeof head, 0};
  ZSTD_inBuffer in{block.data() + sizeof kMagic, block.size() - sizeof kMagic, 0};
  while (out.pos < out.size) {
    const size_t r = ZSTD_decompressStream(d, &out, &in);
    if (ZSTD_isError(r)) throw CodecError(std::string("corrupt height block (") + ZSTD_getErrorName(r) + ")");
    if (r == 0 || (in.pos == in.size && out.pos < out.size)) break;
  }
  ZSTD_DCtx_reset(d, ZSTD_reset_session_only);
  if (out.pos < sizeof head || head[0] > uint8_t(HeightQuantization::kPrecision))
    throw CodecError("corrupt or truncated height block (header)");
  return HeightQuantization(head[0]);
}

void decodeHeights(std::span<const uint8_t> block, uint32_t side, std::span<float> out) {
  const size_t n = size_t(side) * side;
  if (out.size() != n) throw std::invalid_argument("decodeHeights: output is not side^2");
  if (block.size() < sizeof kMagic || std::memcmp(block.data(), kMagic, sizeof kMagic) != 0)
    throw CodecError("not a height block (bad magic)");
  const uint8_t* frame = block.data() + sizeof kMagic;
  const size_t frameBytes = block.size() - sizeof kMagic;
  const unsigned long long size = ZSTD_getFrameContentSize(frame, frameBytes);
  if (size == ZSTD_CONTENTSIZE_ERROR || size == ZSTD_CONTENTSIZE_UNKNOWN || size < kHeaderBytes ||
      size > kHeaderBytes + 4 * n)
    throw CodecError("corrupt or truncated height block (frame header)");
  thread_local std::vector<uint8_t> raw;
  raw.resize(size);
  const size_t got = ZSTD_decompressDCtx(decompressor(), raw.data(), raw.size(), frame, frameBytes);
  if (ZSTD_isError(got) || got != size)
    throw CodecError(std::string("corrupt or truncated height block (") +
                     (ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short") + ")");
  const uint8_t mode = raw[0], planes = raw[1];
  uint32_t blockSide = 0;
  double step = 0.0;
  std::memcpy(&blockSide, raw.data() + 4, 4);
  std::memcpy(&step, raw.data() + 8, 8);
  if (mode > uint8_t(HeightQuantization::kPrecision) || planes < 1 || planes > 4 || !(step > 0.0) ||
      !std::isfinite(step))
    throw CodecError("corrupt height block (header)");
  if (blockSide != side || size != kHeaderBytes + size_t(planes) * n)
    throw CodecError("height block of side " + std::to_string(blockSide) + ", expected " + std::to_string(side));
  // Residuals back, then the Lorenzo reconstruction in the encoder's order.
  thread_local std::vector<int32_t> q;
  q.resize(n);
  const uint8_t* base = raw.data() + kHeaderBytes;
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) {
      const size_t i = size_t(y) * side + x;
      uint32_t z = 0;
      for (uint8_t p = 0; p < planes; ++p) z |= uint32_t(base[size_t(p) * n + i]) << (8 * p);
      const int64_t v = predict(q.data(), side, x, y) + unzigzag(z);
      if (v < -kMaxSteps || v > kMaxSteps) throw CodecError("corrupt height block (value out of range)");
      q[i] = int32_t(v);
      out[i] = float(double(v) * step);
    }
}

}  // namespace gimlod
