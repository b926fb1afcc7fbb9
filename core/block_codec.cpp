#include "core/block_codec.h"
#include "core/vector_clones.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <unordered_set>

#include <zstd.h>

namespace gimlod {
namespace {

constexpr char kHeightMagic[4] = {'G', 'H', 'B', '1'};
constexpr char kPositionMagic[4] = {'G', 'P', 'B', '1'};
constexpr char kNormalMagic[4] = {'G', 'N', 'B', '1'};
constexpr char kColourMagic[4] = {'G', 'C', 'B', '1'};
constexpr char kBytesMagic[4] = {'G', 'Z', 'B', '1'};
constexpr char kBorderNormalMagic[4] = {'G', 'N', 'R', '1'};
constexpr size_t kMagicBytes = 4;
constexpr size_t kIntHeaderBytes = 16;  // inside the frame: quantization, planes, channels, side, step
constexpr size_t kByteHeaderBytes = 8;  // inside the frame: kind, channels, side
// |quantized| bounds: integers (exact in float up to 2^24, and beyond on their own lattice) and
// steps (float(q * step) / step rounds back to q below 2^23, so quantizing is idempotent).
constexpr int64_t kMaxIntegerSteps = int64_t{1} << 28;
constexpr int64_t kMaxSteps = int64_t{1} << 23;
// How far (lattice steps, per coordinate) settlePositions looks beside a sample's nearest lattice
// point for one no other sample holds.
constexpr int64_t kSettleReach = 3;
constexpr int kLevel = 3;
// Positions are coded once per mesh build, and their byte planes at level 9 take 5-6% fewer bytes
// and decode 10% faster than at 3 (igea and the bunny's default atlases; at 12, 1% fewer still).
// Heights keep level 3: a terrain build codes billions of samples, at about a third of the speed.
constexpr int kPositionLevel = 9;

struct CCtxFree {
  void operator()(ZSTD_CCtx* c) const { ZSTD_freeCCtx(c); }
};
struct DCtxFree {
  void operator()(ZSTD_DCtx* c) const { ZSTD_freeDCtx(c); }
};

ZSTD_CCtx* compressor() {
  thread_local std::unique_ptr<ZSTD_CCtx, CCtxFree> c([] {
    ZSTD_CCtx* x = ZSTD_createCCtx();
    ZSTD_CCtx_setParameter(x, ZSTD_c_checksumFlag, 1);  // (frame() sets the level)
    return x;
  }());
  return c.get();
}

ZSTD_DCtx* decompressor() {
  thread_local std::unique_ptr<ZSTD_DCtx, DCtxFree> d(ZSTD_createDCtx());
  return d.get();
}

// magic + one zstd frame (with its checksum) of raw, at zstd level `level`.
std::vector<uint8_t> frame(const char (&magic)[4], std::span<const uint8_t> raw, int level = kLevel) {
  std::vector<uint8_t> out(kMagicBytes + ZSTD_compressBound(raw.size()));
  std::memcpy(out.data(), magic, kMagicBytes);
  ZSTD_CCtx* c = compressor();
  ZSTD_CCtx_setParameter(c, ZSTD_c_compressionLevel, level);
  const size_t written = ZSTD_compress2(c, out.data() + kMagicBytes, out.size() - kMagicBytes, raw.data(), raw.size());
  if (ZSTD_isError(written)) throw std::runtime_error(std::string("block codec: zstd: ") + ZSTD_getErrorName(written));
  out.resize(kMagicBytes + written);
  return out;
}

// The raw bytes of a block made by frame(), checked against its magic, its frame checksum and a
// size in [minSize, maxSize]. The buffer is the thread's own, valid until its next call.
const std::vector<uint8_t>& unframe(std::span<const uint8_t> block, const char (&magic)[4], const char* what,
                                    size_t minSize, size_t maxSize) {
  if (block.size() < kMagicBytes || std::memcmp(block.data(), magic, kMagicBytes) != 0)
    throw CodecError(std::string("not a ") + what + " block (bad magic)");
  const uint8_t* f = block.data() + kMagicBytes;
  const size_t fBytes = block.size() - kMagicBytes;
  const unsigned long long size = ZSTD_getFrameContentSize(f, fBytes);
  if (size == ZSTD_CONTENTSIZE_ERROR || size == ZSTD_CONTENTSIZE_UNKNOWN || size < minSize || size > maxSize)
    throw CodecError(std::string("corrupt or truncated ") + what + " block (frame header)");
  thread_local std::vector<uint8_t> raw;
  raw.resize(size);
  const size_t got = ZSTD_decompressDCtx(decompressor(), raw.data(), raw.size(), f, fBytes);
  if (ZSTD_isError(got) || got != size)
    throw CodecError(std::string("corrupt or truncated ") + what + " block (" +
                     (ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short") + ")");
  return raw;
}

inline uint32_t zigzag(int32_t r) { return (uint32_t(r) << 1) ^ uint32_t(r >> 31); }
inline int32_t unzigzag(uint32_t z) { return int32_t(z >> 1) ^ -int32_t(z & 1); }
inline uint8_t zigzag8(uint8_t r) {
  const int8_t s = int8_t(r);
  return uint8_t((uint8_t(s) << 1) ^ uint8_t(s >> 7));
}
inline uint8_t unzigzag8(uint8_t z) { return uint8_t((z >> 1) ^ uint8_t(-int(z & 1))); }

// The Lorenzo prediction of sample (x, y) of an interleaved image (stride channels) from its
// decoded neighbours (left, below, below-left); the first row and column use their one neighbour,
// the first sample 0.
inline int64_t predict(const int32_t* q, uint32_t side, uint32_t stride, uint32_t x, uint32_t y) {
  const size_t row = size_t(side) * stride;
  const size_t i = (size_t(y) * side + x) * stride;
  if (x > 0 && y > 0) return int64_t(q[i - stride]) + q[i - row] - q[i - row - stride];
  if (x > 0) return q[i - stride];
  if (y > 0) return q[i - row];
  return 0;
}

// A side of 2^k + 1 samples, k >= 1: the sides the interpolation order covers.
bool interpolatedSide(uint32_t side) { return side >= 3 && std::has_single_bit(side - 1); }

// One sample of the interpolation order (below): its place, the spacing and the pass.
struct OrderStep {
  uint32_t x = 0, y = 0, h = 0;
  int pass = 0;
};

// The interpolation order of a block of side 2^k + 1: its four corners, then for each spacing h
// from (side - 1) / 2 down to 1, the midpoints of the rows' intervals of 2h (between (x - h, y) and
// (x + h, y)), those of the columns' (between (x, y - h) and (x, y + h)), and the centres (between
// all four of those). f(x, y, h, pass): pass 0 a corner, 1 a row's midpoint, 2 a column's, 3 a centre.
template <class F>
void forEachInterpolated(uint32_t side, F&& f) {
  const uint32_t m = side - 1;
  f(0u, 0u, m, 0);
  f(m, 0u, m, 0);
  f(0u, m, m, 0);
  f(m, m, m, 0);
  for (uint32_t h = m / 2; h >= 1; h /= 2) {
    for (uint32_t y = 0; y <= m; y += 2 * h)
      for (uint32_t x = h; x < m; x += 2 * h) f(x, y, h, 1);
    for (uint32_t y = h; y < m; y += 2 * h)
      for (uint32_t x = 0; x <= m; x += 2 * h) f(x, y, h, 2);
    for (uint32_t y = h; y < m; y += 2 * h)
      for (uint32_t x = h; x < m; x += 2 * h) f(x, y, h, 3);
  }
}

// The same for bytes, clamped to [0, 255]; the first sample 128.
inline uint8_t predictByte(const uint8_t* b, uint32_t side, uint32_t stride, uint32_t x, uint32_t y) {
  const size_t row = size_t(side) * stride;
  const size_t i = (size_t(y) * side + x) * stride;
  if (x > 0 && y > 0) return uint8_t(std::clamp(int(b[i - stride]) + b[i - row] - b[i - row - stride], 0, 255));
  if (x > 0) return b[i - stride];
  if (y > 0) return b[i - row];
  return 128;
}

// ---- position blocks with planar squares ----------------------------------------------------

// A position block may hold planar squares: squares of s intervals (s = side - 1, its halves, ...
// down to 2, on the grid of multiples of s) whose samples all lie where the render grids' two
// triangles of the square's corners put them, rounded on the lattice (planarSquareSample). Their
// corners are coded; their other samples are not, but interpolated. Squares are taken largest
// first, and a square's samples that a larger one already placed, or that lie on a block edge on
// the chart's border, are not its to place. Body (flag kFlagPlanar): the header (flags 1 | 2), the
// first sample, u8 chart border sides, the squares' bits (largest first, row order within a size,
// one per square not inside a planar one, low bit first), then the residuals: per size, largest
// first, the corners of that size's planar squares not yet known, in row order, each predicted by
// Lorenzo on its size's grid (from the neighbours known, else fewer); then every sample still
// unknown, in row order, by Lorenzo.
constexpr uint8_t kFlagPlanar = 2;

// Which squares are planar: per size level l (squares of (side - 1) >> l intervals, 2^l a side),
// row-major: 1 planar, 0 not, 2 inside a planar square of a larger size.
using PlanarSquares = std::vector<std::vector<uint8_t>>;

inline uint32_t squareLevels(uint32_t side) { return side >= 3 ? uint32_t(std::countr_zero(side - 1)) : 0; }

// Settles level l's squares (the larger ones settled): inside a planar one, else decide(x, y).
template <typename Decide>
void settleLevel(PlanarSquares& squares, uint32_t l, Decide&& decide) {
  const uint32_t n = 1u << l;
  squares.resize(std::max<size_t>(squares.size(), l + 1));
  std::vector<uint8_t>& sq = squares[l];
  sq.assign(size_t(n) * n, 0);
  for (uint32_t y = 0; y < n; ++y)
    for (uint32_t x = 0; x < n; ++x) {
      const uint8_t parent = l == 0 ? 0 : squares[l - 1][size_t(y / 2) * (n / 2) + x / 2];
      sq[size_t(y) * n + x] = parent != 0 ? 2 : decide(x, y) ? 1 : 0;
    }
}

// The prediction of sample i coded at `spacing` from the neighbours on that spacing's grid known
// by then (bit 1 the left one, 2 the one below, 4 the lower-left one too): Lorenzo from all three,
// else the left one, else the one below, else the first sample; at spacing 1, where every earlier
// sample is known, Lorenzo as predict() has it. In wrapping unsigned arithmetic; v(j) reads
// sample j's value.
template <typename Value>
inline uint32_t predictFrom(uint8_t neighbours, uint32_t side, uint32_t i, uint32_t spacing, Value&& v) {
  if (neighbours & 4) return v(i - spacing) + v(i - spacing * side) - v(i - spacing - spacing * side);
  if (neighbours & 1) return v(i - spacing);
  if (neighbours & 2) return v(i - spacing * side);
  return v(0);
}

// What the encoder's traversal of a position block works on: q, the block's 3 interleaved channels
// of side^2 samples (the planar squares' samples placed in it as it goes); known, per sample, bit 1
// once it is coded or placed and bit 2 on the chart's border; the squares settled so far.
struct PlanarTraversal {
  std::vector<uint32_t> q;
  std::vector<uint8_t> known;
  PlanarSquares squares;
};

// The encoder's traversal (decodePlanar follows it) of a block of side^2 samples whose edges on its
// chart's border are chartBorderSides (kChartBorder* bits), in `traversal` (its known and squares
// reset first). decide(l, x, y) settles an uncovered square at level l before anything of that
// size is coded; code(i, spacing) codes sample i from its neighbours at that spacing
// (predictPlanar) while squares are coded, then, with spacing 1, every sample still unknown in row
// order (all its Lorenzo neighbours known by then). The planar squares' samples are placed in q.
template <typename Decide, typename Code>
void planarPasses(uint32_t side, uint8_t chartBorderSides, PlanarTraversal& traversal, Decide&& decide, Code&& code) {
  std::vector<uint32_t>& q = traversal.q;
  std::vector<uint8_t>& known = traversal.known;
  PlanarSquares& squares = traversal.squares;
  const uint32_t levels = squareLevels(side), last = side - 1;
  known.assign(size_t(side) * side, 0);
  known[0] = 1;  // the first sample: in the header
  // Bit 1: known. Bit 2: on the chart's border, never placed by a square (coded in row order).
  for (uint32_t t = 0; t < side; ++t) {
    if (chartBorderSides & kChartBorderBottom) known[t] |= 2;
    if (chartBorderSides & kChartBorderTop) known[size_t(last) * side + t] |= 2;
    if (chartBorderSides & kChartBorderLeft) known[size_t(t) * side] |= 2;
    if (chartBorderSides & kChartBorderRight) known[size_t(t) * side + last] |= 2;
  }
  squares.clear();
  for (uint32_t l = 0; l < levels; ++l) {
    const uint32_t n = 1u << l, s = last >> l;
    settleLevel(squares, l, [&](uint32_t x, uint32_t y) { return decide(l, x, y); });
    const std::vector<uint8_t>& sq = squares[l];
    auto planar = [&](int64_t x, int64_t y) {
      return x >= 0 && y >= 0 && x < n && y < n && sq[size_t(y) * n + size_t(x)] == 1;
    };
    for (uint32_t gy = 0; gy <= n; ++gy)
      for (uint32_t gx = 0; gx <= n; ++gx) {
        const uint32_t i = gy * s * side + gx * s;
        if ((known[i] & 1) || !(planar(gx - 1, gy - 1) || planar(gx, gy - 1) || planar(gx - 1, gy) || planar(gx, gy)))
          continue;
        code(i, s);
        known[i] |= 1;
      }
    for (uint32_t y = 0; y < n; ++y)
      for (uint32_t x = 0; x < n; ++x) {
        if (sq[size_t(y) * n + x] != 1) continue;
        const uint32_t x0 = x * s, y0 = y * s;
        const size_t c00 = size_t(y0) * side + x0, c10 = c00 + s, c01 = c00 + size_t(s) * side, c11 = c01 + s;
        int64_t corner[3][4];
        for (uint32_t c = 0; c < 3; ++c) {
          corner[c][0] = int32_t(q[c00 * 3 + c]), corner[c][1] = int32_t(q[c10 * 3 + c]);
          corner[c][2] = int32_t(q[c01 * 3 + c]), corner[c][3] = int32_t(q[c11 * 3 + c]);
        }
        for (uint32_t dy = 0; dy <= s; ++dy) {
          uint8_t* k = known.data() + size_t(y0 + dy) * side + x0;
          for (uint32_t dx = 0; dx <= s; ++dx) {
            if (k[dx]) continue;
            uint32_t* o = q.data() + (size_t(y0 + dy) * side + x0 + dx) * 3;
            for (uint32_t c = 0; c < 3; ++c)
              o[c] = uint32_t(planarSquareSample(corner[c][0], corner[c][1], corner[c][2], corner[c][3], s, dx, dy));
            k[dx] = 1;
          }
        }
      }
  }
  // The rest in row order, each from its left, lower and lower-left neighbours, known by now.
  for (uint32_t i = 1; i < side * side; ++i)
    if (!(known[i] & 1)) code(i, 1), known[i] = 1;
}

// The prediction of channel c of sample i coded at `spacing` (planarPasses), from the neighbours
// `known` then.
inline uint32_t predictPlanar(const std::vector<uint32_t>& q, const std::vector<uint8_t>& known, uint32_t side,
                              uint32_t i, uint32_t spacing, uint32_t c) {
  const uint32_t x = i % side, y = i / side;
  const bool l = x >= spacing && (known[i - spacing] & 1), b = y >= spacing && (known[i - spacing * side] & 1);
  const bool lb = l && b && (known[i - spacing - spacing * side] & 1);
  return predictFrom(uint8_t(l | b << 1 | lb << 2), side, i, spacing, [&](uint32_t j) { return q[size_t(j) * 3 + c]; });
}

// ---- quantized integers (heights: 1 channel; positions: 3) ------------------------------------

// The body of an integer block (inside its zstd frame): a 16-byte header (u8 quantization, u8
// planes, u8 channels, u8 flags, u32 side, f64 step); with flag 1, the first sample's channels as
// i32; then the residuals as byte planes. Without flag 1 (blocks written before
// it), the first sample is coded as a residual from 0, which takes a plane or two more.
constexpr uint8_t kFlagFirstSample = 1;
constexpr uint8_t kFlagInterpolated = 4;  // residuals in forEachInterpolated's order

// A kind of integer block: its magic, its name in messages, its channels, and the zstd level it is
// coded at.
struct IntBlockKind {
  const char (&magic)[4];
  const char* what;
  uint8_t channels;
  int level;
};
constexpr IntBlockKind kHeightBlocks{kHeightMagic, "height", 1, kLevel};
constexpr IntBlockKind kPositionBlocks{kPositionMagic, "position", 3, kPositionLevel};

// How an integer body's header describes its samples.
struct IntBodyHeader {
  HeightQuantization mode = HeightQuantization::kPrecision;
  double step = 1.0;
  uint32_t side = 0;
  uint8_t channels = 0;
  uint8_t flags = 0;  // kFlagFirstSample, with kFlagInterpolated for that order
};

// The body of zigzagged residuals z (channels interleaved, sample by sample in the order the
// header's flags name), the first sample of q (channels interleaved) in the header: byte planes
// per channel (low bytes first), planes above the highest non-zero byte left out.
std::vector<uint8_t> intBody(const IntBodyHeader& h, const std::vector<uint32_t>& z, const int32_t* first) {
  const uint8_t channels = h.channels;
  const size_t n = size_t(h.side) * h.side;
  uint32_t all = 0;
  for (const uint32_t r : z) all |= r;
  uint8_t planes = 1;
  while (planes < 4 && (all >> (8 * planes)) != 0) ++planes;
  const size_t head = kIntHeaderBytes + 4 * size_t(channels);
  std::vector<uint8_t> raw(head + size_t(planes) * channels * n);
  raw[0] = uint8_t(h.mode);
  raw[1] = planes;
  raw[2] = channels;
  raw[3] = h.flags;
  std::memcpy(raw.data() + 4, &h.side, 4);
  std::memcpy(raw.data() + 8, &h.step, 8);
  std::memcpy(raw.data() + kIntHeaderBytes, first, 4 * size_t(channels));
  for (uint32_t c = 0; c < channels; ++c)
    for (uint8_t p = 0; p < planes; ++p) {
      uint8_t* plane = raw.data() + head + (size_t(c) * planes + p) * n;
      for (size_t i = 0; i < n; ++i) plane[i] = uint8_t(z[i * channels + c] >> (8 * p));
    }
  return raw;
}

// The zigzagged Lorenzo residuals of side^2 samples q (channels interleaved), in row order; the
// first sample's 0 (it goes to the header).
std::vector<uint32_t> lorenzoResiduals(const std::vector<int32_t>& q, uint32_t side, uint32_t channels) {
  std::vector<uint32_t> z(size_t(side) * side * channels);
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x)
      for (uint32_t c = 0; c < channels; ++c) {
        const size_t i = (size_t(y) * side + x) * channels + c;
        z[i] = i < channels ? 0 : zigzag(int32_t(int64_t(q[i]) - predict(q.data() + c, side, channels, x, y)));
      }
  return z;
}

// What residuals cost, roughly, before the entropy coder: their bits, summed (0 for a 0).
uint64_t residualBits(const std::vector<uint32_t>& z) {
  uint64_t bits = 0;
  for (const uint32_t r : z) bits += uint64_t(std::bit_width(r));
  return bits;
}

// A block of `kind` of side^2 quantized samples q (channels interleaved), quantized as `mode` to `step`.
std::vector<uint8_t> encodeInts(const IntBlockKind& kind, const std::vector<int32_t>& q, uint32_t side,
                                HeightQuantization mode, double step) {
  const IntBodyHeader h{mode, step, side, kind.channels, kFlagFirstSample};
  return frame(kind.magic, intBody(h, lorenzoResiduals(q, side, kind.channels), q.data()), kind.level);
}

// The interpolated prediction of channel c of sample (x, y) in forEachInterpolated's order (pass,
// spacing h) from the values already decoded (channels interleaved): the mean of the pass's
// neighbours, rounded down; the first corner's value for the other corners (the first one is in
// the header: 0).
template <class T>  // int32_t (decoded values) or int64_t (the settler's lattice points)
inline int64_t interpolatedValue(const T* q, uint32_t side, uint32_t channels, uint32_t c, const OrderStep& o) {
  const uint32_t x = o.x, y = o.y, h = o.h;
  const auto at = [&](uint32_t u, uint32_t v) { return int64_t(q[(size_t(v) * side + u) * channels + c]); };
  switch (o.pass) {
    case 1: return (at(x - h, y) + at(x + h, y) + 1) >> 1;
    case 2: return (at(x, y - h) + at(x, y + h) + 1) >> 1;
    case 3: return (at(x - h, y - h) + at(x + h, y + h) + 1) >> 1;
    default: return x == 0 && y == 0 ? 0 : at(0, 0);
  }
}

// The zigzagged residuals of side^2 samples q (channels interleaved) in the interpolation order
// (side 2^k + 1), sample by sample; the first sample's 0 (it goes to the header).
std::vector<uint32_t> interpolatedResiduals(const std::vector<int32_t>& q, uint32_t side, uint32_t channels) {
  std::vector<uint32_t> z(size_t(side) * side * channels);
  size_t k = 0;
  forEachInterpolated(side, [&](uint32_t x, uint32_t y, uint32_t h, int pass) {
    for (uint32_t c = 0; c < channels; ++c) {
      const int64_t v = q[(size_t(y) * side + x) * channels + c];
      z[k * channels + c] =
          k == 0 ? 0 : zigzag(int32_t(v - interpolatedValue(q.data(), side, channels, c, {x, y, h, pass})));
    }
    ++k;
  });
  return z;
}

// The body of a position block with planar squares (chartBorderSides: kChartBorder* bits), or
// empty when it has none.
std::vector<uint8_t> planarBody(const std::vector<int32_t>& q, uint32_t side, double step, uint8_t chartBorderSides) {
  if (squareLevels(side) == 0 || !std::has_single_bit(side - 1)) return {};
  PlanarTraversal traversal;
  traversal.q.assign(q.begin(), q.end());
  const std::vector<uint32_t>& v = traversal.q;
  const std::vector<uint8_t>& known = traversal.known;
  std::vector<uint8_t> bits;
  size_t nbits = 0;
  bool any = false;
  std::vector<uint32_t> z;
  const uint32_t last = side - 1;
  auto decide = [&](uint32_t l, uint32_t x, uint32_t y) {
    const uint32_t s = last >> l, x0 = x * s, y0 = y * s;
    bool flat = true;
    for (uint32_t dy = 0; dy <= s && flat; ++dy)
      for (uint32_t dx = 0; dx <= s && flat; ++dx) {
        const uint32_t u = x0 + dx, w = y0 + dy, i = w * side + u;
        // Samples placed before, on the chart's border (planarPasses' known), and the corners.
        if (known[i] || (dx % s == 0 && dy % s == 0)) continue;
        for (uint32_t c = 0; c < 3 && flat; ++c) {
          auto at = [&](uint32_t a, uint32_t b) { return int64_t(q[(size_t(b) * side + a) * 3 + c]); };
          flat =
              at(u, w) == planarSquareSample(at(x0, y0), at(x0 + s, y0), at(x0, y0 + s), at(x0 + s, y0 + s), s, dx, dy);
        }
      }
    if (bits.size() * 8 <= nbits) bits.push_back(0);
    bits[nbits / 8] |= uint8_t(flat) << (nbits % 8);
    ++nbits;
    any |= flat;
    return flat;
  };
  auto code = [&](uint32_t i, uint32_t spacing) {
    for (uint32_t c = 0; c < 3; ++c)
      z.push_back(zigzag(int32_t(v[size_t(i) * 3 + c] - predictPlanar(v, known, side, i, spacing, c))));
  };
  planarPasses(side, chartBorderSides, traversal, decide, code);
  if (!any) return {};
  const size_t m = z.size() / 3;
  uint32_t all = 0;
  for (uint32_t r : z) all |= r;
  uint8_t planes = 1;
  while (planes < 4 && (all >> (8 * planes)) != 0) ++planes;
  const size_t head = kIntHeaderBytes + 12;
  std::vector<uint8_t> raw(head + 1 + bits.size() + size_t(planes) * 3 * m);
  raw[0] = uint8_t(HeightQuantization::kPrecision);
  raw[1] = planes;
  raw[2] = 3;
  raw[3] = kFlagFirstSample | kFlagPlanar;
  std::memcpy(raw.data() + 4, &side, 4);
  std::memcpy(raw.data() + 8, &step, 8);
  std::memcpy(raw.data() + kIntHeaderBytes, q.data(), 12);
  raw[head] = chartBorderSides;
  std::memcpy(raw.data() + head + 1, bits.data(), bits.size());
  uint8_t* body = raw.data() + head + 1 + bits.size();
  for (uint32_t c = 0; c < 3; ++c)
    for (uint8_t p = 0; p < planes; ++p) {
      uint8_t* plane = body + (size_t(c) * planes + p) * m;
      for (size_t j = 0; j < m; ++j) plane[j] = uint8_t(z[j * 3 + c] >> (8 * p));
    }
  return raw;
}

// A block's decoded values: n = side^2 per channel, channel c at q + c n, each at most `bound`
// from 0 and standing for its multiple of `step`.
struct DecodedPlanes {
  const uint32_t* q = nullptr;
  size_t n = 0;
  uint32_t channels = 0;
  double step = 0.0;
  uint32_t bound = 0;
};

// Checks the decoded values of samples [at, at + count) and stores them as interleaved floats
// (channels a sample) in out: hi gathers the largest q + bound, unsigned (a value below -bound
// wraps past 2 bound too), for the caller's one check.
inline void storeFloats(const DecodedPlanes& planes, size_t at, size_t count, uint32_t& hi, float* out) {
  const uint32_t* q = planes.q;
  const size_t n = planes.n;
  const uint32_t channels = planes.channels, bound = planes.bound;
  const double step = planes.step;
  float* o = out + at * channels;
  uint32_t h = hi;
  if (channels == 3) {  // (one loop for the three: a third fewer cycles)
    const uint32_t *a0 = q + at, *a1 = a0 + n, *a2 = a1 + n;
    for (size_t x = 0; x < count; ++x) {
      h = std::max(h, a0[x] + bound), h = std::max(h, a1[x] + bound), h = std::max(h, a2[x] + bound);
      o[3 * x] = float(double(int32_t(a0[x])) * step);
      o[3 * x + 1] = float(double(int32_t(a1[x])) * step);
      o[3 * x + 2] = float(double(int32_t(a2[x])) * step);
    }
  } else {
    for (uint32_t ch = 0; ch < channels; ++ch) {
      const uint32_t* a = q + size_t(ch) * n + at;
      for (size_t x = 0; x < count; ++x) {
        h = std::max(h, a[x] + bound);
        o[x * channels + ch] = float(double(int32_t(a[x])) * step);
      }
    }
  }
  hi = h;
}

// c ? a : b without a branch, in a form the compiler vectorizes (a select it would not).
inline uint32_t pick(bool c, uint32_t a, uint32_t b) {
  const uint32_t m = 0u - uint32_t(c);
  return (a & m) | (b & ~m);
}

// A planar square of a block `side` samples a side: its corner (0, 0) at sample c00, its level l
// and its s intervals.
struct PlanarSquare {
  uint32_t side = 0;
  size_t c00 = 0;
  uint32_t l = 0;
  uint32_t s = 0;
};

// Per planar square sq, its s a constant S where one is given (the compiler then unrolls the loops
// of the small squares, the most frequent): paintSquare marks its footprint and its corners with
// its level l where they hold a larger level (cls, corner); placeSquare places its samples where
// cls[] is l in q (3 channels, channel c at q + c n), as planarSquareSample puts them, in wrapping
// 32-bit arithmetic: the corners of a valid block lie within 2^23 steps, so every sum of the two
// triangles' weights (s in all) does within s 2^23 <= 2^31, and comes out exact.
template <uint32_t S>
inline void paintSquare(uint32_t* cls, uint32_t* corner, const PlanarSquare& sq) {
  const uint32_t side = sq.side, l = sq.l;
  const size_t c00 = sq.c00;
  const uint32_t s = S ? S : sq.s;
#pragma GCC unroll 9
  for (uint32_t dy = 0; dy <= s; ++dy)
#pragma GCC unroll 9
    for (uint32_t dx = 0; dx <= s; ++dx)
      cls[c00 + size_t(dy) * side + dx] = std::min(cls[c00 + size_t(dy) * side + dx], l);
  for (const size_t c : {c00, c00 + s, c00 + size_t(s) * side, c00 + size_t(s) * side + s})
    corner[c] = std::min(corner[c], l);
}
template <uint32_t S>
inline void placeSquare(uint32_t* q, size_t n, const uint32_t* cls, const PlanarSquare& sq) {
  const uint32_t side = sq.side, l = sq.l;
  const size_t c00 = sq.c00;
  const uint32_t s = S ? S : sq.s, shift = uint32_t(std::countr_zero(s)), half = s / 2;
  const size_t up = size_t(s) * side;
  for (uint32_t c = 0; c < 3; ++c) {
    uint32_t* qc = q + size_t(c) * n + c00;
    const uint32_t q00 = qc[0], q10 = qc[s], q01 = qc[up], q11 = qc[up + s];
#pragma GCC unroll 9
    for (uint32_t dy = 0; dy <= s; ++dy) {
      const uint32_t* lv = cls + c00 + size_t(dy) * side;
      uint32_t* row = qc + size_t(dy) * side;
      uint32_t v = s * q00 + dy * (q01 - q00) + half;  // dx < dy: up the left edge, then along
#pragma GCC unroll 9
      for (uint32_t dx = 0; dx < dy; ++dx, v += q11 - q01)
        row[dx] = pick(lv[dx] == l, uint32_t(int32_t(v) >> shift), row[dx]);
      v = s * q00 + dy * (q11 - q00) + half;  // dx >= dy: along the diagonal, then along
#pragma GCC unroll 9
      for (uint32_t dx = dy; dx <= s; ++dx, v += q10 - q00)
        row[dx] = pick(lv[dx] == l, uint32_t(int32_t(v) >> shift), row[dx]);
    }
  }
}

// Places the samples of level l's squares of 2 intervals in q (3 channels, channel c at q + c n)
// where cls[] is l: each lies halfway between two corners, rounded half up, as planarSquareSample
// puts it: on a square's edge between the edge's ends, inside it between the corners (0, 0) and
// (2, 2). Whole rows at a time, in loops without a branch per sample.
void placeMidpoints(uint32_t* q, size_t n, const uint32_t* cls, uint32_t side, uint32_t l) {
  auto mid = [](uint32_t a, uint32_t b) { return uint32_t(int32_t(a + b + 1) >> 1); };
  thread_local std::vector<uint32_t> between;
  between.resize(side);
  uint32_t* t = between.data();
  for (uint32_t y = 0; y < side; ++y) {
    const uint32_t* lv = cls + size_t(y) * side;
    if (std::find(lv, lv + side, l) == lv + side) continue;
    for (uint32_t c = 0; c < 3; ++c) {
      uint32_t* row = q + size_t(c) * n + size_t(y) * side;
      if (y % 2 == 0) {  // a row of corners: between the two beside
        for (uint32_t x = 1; x + 1 < side; ++x) t[x] = mid(row[x - 1], row[x + 1]);
      } else {  // between two rows of corners: below and above on their columns, else diagonally
        const uint32_t *below = row - side, *above = row + side;
        t[0] = mid(below[0], above[0]);
        t[side - 1] = mid(below[side - 1], above[side - 1]);
        for (uint32_t x = 1; x + 1 < side; ++x) {
          const uint32_t odd = 0u - (x & 1u);
          t[x] = (mid(below[x - 1], above[x + 1]) & odd) | (mid(below[x], above[x]) & ~odd);
        }
      }
      for (uint32_t x = 0; x < side; ++x) row[x] = pick(lv[x] == l, t[x], row[x]);
    }
  }
}

// Decodes a position block body with planar squares (raw: its whole body; head: where its chart
// border byte is) into out. The encoder's traversal (planarPasses) follows from the level of the
// largest planar square whose closed footprint holds a sample (for a sample on the chart's border,
// only as the square's corner): a sample on that level's grid is a corner, coded at that level and
// known to the corners after it; any other is placed there; a sample in no planar square is coded
// with the rest. So the decoder classes the samples first, painting the planar squares one by one,
// then decodes the values, each channel on its own, in loops without a branch per sample.
void decodePlanar(const std::vector<uint8_t>& raw, size_t head, uint32_t side, double step, std::span<float> out) {
  if (squareLevels(side) == 0 || !std::has_single_bit(side - 1) || raw.size() <= head || raw[head] > 15)
    throw CodecError("corrupt position block (planar squares)");
  const uint8_t border = raw[head], planes = raw[1];
  const uint32_t levels = squareLevels(side), last = side - 1;
  const size_t n = size_t(side) * side, bitsAt = head + 1;
  // A sample's class: its level, with kCorner for a corner coded at it; kRest in no planar square.
  constexpr uint32_t kRest = 0xff, kCorner = 0x40, kLevel = 0x3f;
  thread_local std::vector<uint32_t> cls, corner;  // (32-bit: selects by them vectorize)
  thread_local PlanarSquares squares;
  thread_local std::vector<uint32_t> q, r, zeros;
  size_t nbits = 0;
  squares.clear();
  for (uint32_t l = 0; l < levels; ++l)
    settleLevel(squares, l, [&](uint32_t, uint32_t) {
      if (bitsAt + nbits / 8 >= raw.size()) throw CodecError("truncated position block (planar squares)");
      const bool planar = ((raw[bitsAt + nbits / 8] >> (nbits % 8)) & 1u) != 0;
      ++nbits;
      return planar;
    });
  // Calls f(c00) for each planar square of level l, c00 its corner (0, 0).
  auto eachSquare = [&](uint32_t l, auto&& f) {
    const uint32_t m = 1u << l, s = last >> l;
    const uint8_t* sq = squares[l].data();
    for (uint32_t y = 0; y < m; ++y)
      for (uint32_t x = 0; x < m; ++x)
        if (sq[size_t(y) * m + x] == 1) f(size_t(y) * s * side + size_t(x) * s);
  };
  // cls: the level of the largest planar square whose footprint holds the sample; corner: of the
  // largest whose corner it is.
  cls.assign(n, kRest);
  corner.assign(n, kRest);
  for (uint32_t l = 0; l < levels; ++l) {
    const uint32_t s = last >> l;
    eachSquare(l, [&](size_t c00) {
      const PlanarSquare sq{side, c00, l, s};
      if (s == 2)
        paintSquare<2>(cls.data(), corner.data(), sq);
      else if (s == 4)
        paintSquare<4>(cls.data(), corner.data(), sq);
      else
        paintSquare<0>(cls.data(), corner.data(), sq);
    });
  }
  for (uint32_t t = 0; t < side; ++t) {  // the chart's border: only as a corner
    if (border & kChartBorderBottom) cls[t] = corner[t];
    if (border & kChartBorderTop) cls[size_t(last) * side + t] = corner[size_t(last) * side + t];
    if (border & kChartBorderLeft) cls[size_t(t) * side] = corner[size_t(t) * side];
    if (border & kChartBorderRight) cls[size_t(t) * side + last] = corner[size_t(t) * side + last];
  }
  // The first sample, in the header: known to every level, never coded or placed.
  cls[0] = kCorner;
  size_t corners = 0, rest = 0;
  for (size_t i = 1; i < n; ++i) {
    const uint32_t c = cls[i] | (corner[i] == cls[i] ? kCorner : 0);
    cls[i] = c;
    corners += (c & kCorner) && c != kRest;
    rest += c == kRest;
  }
  const size_t m = corners + rest;
  const size_t body = bitsAt + (nbits + 7) / 8;
  if (raw.size() != body + size_t(planes) * 3 * m) throw CodecError("corrupt position block (size)");

  // The residuals back, per channel (one more, so the rest's loop may read one past its last).
  r.resize(3 * m + 1);
  r[3 * m] = 0;
  for (uint32_t c = 0; c < 3; ++c) {
    const uint8_t* b0 = raw.data() + body + size_t(c) * planes * m;
    uint32_t* rc = r.data() + size_t(c) * m;
    for (size_t j = 0; j < m; ++j) rc[j] = b0[j];
    for (uint32_t p = 1; p < planes; ++p)
      for (size_t j = 0; j < m; ++j) rc[j] |= uint32_t(b0[size_t(p) * m + j]) << (8 * p);
    for (size_t j = 0; j < m; ++j) rc[j] = (rc[j] >> 1) ^ (0u - (rc[j] & 1u));
  }
  q.resize(3 * n);
  for (uint32_t c = 0; c < 3; ++c) std::memcpy(q.data() + size_t(c) * n, raw.data() + kIntHeaderBytes + 4 * c, 4);
  size_t j = 0;
  for (uint32_t l = 0; l < levels; ++l) {
    // The level's corners, in row order, each from its neighbours on the level's grid known by
    // then: those of a level up to l (this level's corners before it, in row order).
    const uint32_t s = last >> l;
    const uint32_t here = l | kCorner;
    for (uint32_t y = 0; y <= last; y += s)
      for (uint32_t x = 0; x <= last; x += s) {
        const uint32_t i = y * side + x;
        if (i == 0 || cls[i] != here) continue;
        const auto known = [&](uint32_t k) { return (cls[k] & kLevel) <= l; };
        const bool left = x > 0 && known(i - s), below = y > 0 && known(i - s * side);
        const uint8_t neighbours = uint8_t(left | below << 1 | (left && below && known(i - s - s * side)) << 2);
        for (uint32_t c = 0; c < 3; ++c) {
          uint32_t* qc = q.data() + size_t(c) * n;
          qc[i] = r[size_t(c) * m + j] + predictFrom(neighbours, side, i, s, [&](uint32_t a) { return qc[a]; });
        }
        ++j;
      }
    // The samples the level's squares placed; squares of 2 intervals, the most frequent, by rows.
    if (s == 2) {
      placeMidpoints(q.data(), n, cls.data(), side, l);
      continue;
    }
    eachSquare(l, [&](size_t c00) {
      const PlanarSquare sq{side, c00, l, s};
      if (s == 4)
        placeSquare<4>(q.data(), n, cls.data(), sq);
      else if (s == 8)
        placeSquare<8>(q.data(), n, cls.data(), sq);
      else
        placeSquare<0>(q.data(), n, cls.data(), sq);
    });
  }
  if (j != corners) throw CodecError("corrupt position block (planar squares)");
  // The rest, row by row: along a row, d = q - (the sample below; 0 on the first row) is the
  // running sum of the residuals (Lorenzo), restarted at each sample known before.
  zeros.assign(side, 0u);
  const uint32_t *r0 = r.data() + j, *r1 = r0 + m, *r2 = r1 + m;
  for (uint32_t y = 0; y < side; ++y) {
    const size_t at = size_t(y) * side;
    const uint32_t* lv = cls.data() + at;
    uint32_t *a0 = q.data() + at, *a1 = a0 + n, *a2 = a1 + n;
    const uint32_t* b0 = y > 0 ? a0 - side : zeros.data();
    const uint32_t* b1 = y > 0 ? a1 - side : zeros.data();
    const uint32_t* b2 = y > 0 ? a2 - side : zeros.data();
    uint32_t d0 = 0, d1 = 0, d2 = 0;
    for (uint32_t x = 0; x < side; ++x) {
      const bool coded = lv[x] == kRest;
      d0 = coded ? d0 + *r0 : a0[x] - b0[x];
      d1 = coded ? d1 + *r1 : a1[x] - b1[x];
      d2 = coded ? d2 + *r2 : a2[x] - b2[x];
      r0 += coded, r1 += coded, r2 += coded;
      a0[x] = b0[x] + d0, a1[x] = b1[x] + d1, a2[x] = b2[x] + d2;
    }
  }
  uint32_t hi = 0;
  storeFloats({q.data(), n, 3, step, uint32_t(kMaxSteps)}, 0, n, hi, out.data());
  if (hi > uint32_t(2 * kMaxSteps)) throw CodecError("corrupt position block (value out of range)");
}

// Decodes the residual planes of an interpolated body (from byte `head` of raw) into out: each
// value its prediction plus its residual, in wrapping unsigned arithmetic (a crafted block cannot
// overflow), then the floats; false when a value lies beyond `shape`'s bound (its q unused).
bool decodeInterpolatedInts(const std::vector<uint8_t>& raw, size_t head, uint32_t side, DecodedPlanes shape,
                            std::span<float> out) {
  const uint32_t channels = shape.channels, planes = raw[1];
  const size_t n = shape.n;
  thread_local std::vector<int32_t> q;  // channels interleaved, as the predictions read them
  thread_local std::vector<uint32_t> byChannel;
  q.resize(n * channels);
  byChannel.resize(n * channels);
  const uint8_t* base = raw.data() + head;
  int32_t first[4] = {0, 0, 0, 0};
  std::memcpy(first, raw.data() + kIntHeaderBytes, 4 * size_t(channels));
  size_t k = 0;
  forEachInterpolated(side, [&](uint32_t x, uint32_t y, uint32_t h, int pass) {
    const size_t s = size_t(y) * side + x;
    for (uint32_t c = 0; c < channels; ++c) {
      const uint8_t* b = base + size_t(c) * planes * n + k;
      uint32_t z = 0;
      for (uint32_t p = 0; p < planes; ++p) z |= uint32_t(b[p * n]) << (8 * p);
      const uint32_t pred =
          k == 0 ? uint32_t(first[c]) : uint32_t(interpolatedValue(q.data(), side, channels, c, {x, y, h, pass}));
      const uint32_t v = pred + uint32_t(unzigzag(z));
      q[s * channels + c] = int32_t(v);
      byChannel[size_t(c) * n + s] = v;
    }
    ++k;
  });
  uint32_t hi = 0;
  shape.q = byChannel.data();
  storeFloats(shape, 0, n, hi, out.data());
  return hi <= 2 * shape.bound;
}

// Decodes a block of `kind` into out (channels * side^2 floats); returns the quantization.
GIMLOD_VECTOR_CLONES
HeightQuantization decodeInts(std::span<const uint8_t> block, const IntBlockKind& kind, uint32_t side,
                              std::span<float> out) {
  const char* what = kind.what;
  const uint8_t channels = kind.channels;
  const size_t n = size_t(side) * side;
  if (out.size() != n * channels) throw std::invalid_argument(std::string("decode ") + what + ": output size");
  const std::vector<uint8_t>& raw =
      unframe(block, kind.magic, what, kIntHeaderBytes, kIntHeaderBytes + 4 * channels + 4 * channels * n);
  const uint8_t mode = raw[0], planes = raw[1], flags = raw[3];
  uint32_t blockSide = 0;
  double step = 0.0;
  std::memcpy(&blockSide, raw.data() + 4, 4);
  std::memcpy(&step, raw.data() + 8, 8);
  if (mode > uint8_t(HeightQuantization::kPrecision) || planes < 1 || planes > 4 || raw[2] != channels ||
      (flags & ~(kFlagFirstSample | kFlagPlanar | kFlagInterpolated)) != 0 || !(step > 0.0) ||
      !(step <= 1e30))  // decoded values stay finite floats
    throw CodecError(std::string("corrupt ") + what + " block (header)");
  const size_t head = kIntHeaderBytes + ((flags & kFlagFirstSample) ? 4 * size_t(channels) : 0);
  if (blockSide == side && (flags & kFlagInterpolated)) {
    if ((flags & kFlagPlanar) || !(flags & kFlagFirstSample) || !interpolatedSide(side) ||
        raw.size() != head + size_t(planes) * channels * n)
      throw CodecError(std::string("corrupt ") + what + " block (header)");
    const int64_t bound = mode == uint8_t(HeightQuantization::kInteger) ? kMaxIntegerSteps : kMaxSteps;
    if (!decodeInterpolatedInts(raw, head, side, {nullptr, n, channels, step, uint32_t(bound)}, out))
      throw CodecError(std::string("corrupt ") + what + " block (value out of range)");
    return HeightQuantization(mode);
  }
  if (blockSide == side && (flags & kFlagPlanar)) {
    if (channels != 3 || !(flags & kFlagFirstSample) || mode != uint8_t(HeightQuantization::kPrecision))
      throw CodecError(std::string("corrupt ") + what + " block (header)");
    decodePlanar(raw, head, side, step, out);
    return HeightQuantization(mode);
  }
  if (blockSide != side)
    throw CodecError(std::string(what) + " block of side " + std::to_string(blockSide) + ", expected " +
                     std::to_string(side));
  if (raw.size() != head + size_t(planes) * channels * n)
    throw CodecError(std::string("corrupt ") + what + " block (size)");
  // Row by row (so a row's work stays in the L1 cache), each channel: the residuals back (byte
  // planes merged and unzigzagged, a vector loop), then q = the row below + the running sum of the
  // row's residuals (Lorenzo: q(x,y) - q(x,y-1) = r(x,y) + q(x-1,y) - q(x-1,y-1)), kept in a
  // register, in wrapping unsigned arithmetic (a crafted block cannot overflow); then the row's
  // range check and its floats.
  thread_local std::vector<uint32_t> q, r;
  q.resize(n * channels);
  r.resize(side);
  uint32_t first[4] = {0, 0, 0, 0};
  if (flags & kFlagFirstSample) std::memcpy(first, raw.data() + kIntHeaderBytes, 4 * size_t(channels));
  const uint8_t* base = raw.data() + head;
  auto unz = [](uint32_t z) { return (z >> 1) ^ (0u - (z & 1u)); };
  const int64_t bound = mode == uint8_t(HeightQuantization::kInteger) ? kMaxIntegerSteps : kMaxSteps;
  // The largest q + bound, unsigned: a value below -bound wraps past 2 bound too.
  uint32_t hi = 0;
  const uint32_t shift = uint32_t(bound), span = uint32_t(2 * bound);
  for (uint32_t y = 0; y < side; ++y) {
    const size_t at = size_t(y) * side;
    for (uint32_t ch = 0; ch < channels; ++ch) {
      const uint8_t *b0 = base + size_t(ch) * planes * n + at, *b1 = b0 + n, *b2 = b1 + n, *b3 = b2 + n;
      uint32_t* rr = r.data();
      switch (planes) {  // one vector loop per plane count
        case 1:
          for (uint32_t x = 0; x < side; ++x) rr[x] = unz(b0[x]);
          break;
        case 2:
          for (uint32_t x = 0; x < side; ++x) rr[x] = unz(b0[x] | uint32_t(b1[x]) << 8);
          break;
        case 3:
          for (uint32_t x = 0; x < side; ++x) rr[x] = unz(b0[x] | uint32_t(b1[x]) << 8 | uint32_t(b2[x]) << 16);
          break;
        default:
          for (uint32_t x = 0; x < side; ++x)
            rr[x] = unz(b0[x] | uint32_t(b1[x]) << 8 | uint32_t(b2[x]) << 16 | uint32_t(b3[x]) << 24);
      }
      if (y == 0) rr[0] += first[ch];
      uint32_t* row = q.data() + size_t(ch) * n + at;
      const uint32_t* below = y > 0 ? row - side : nullptr;
      uint32_t sum = 0;
      if (below)
        for (uint32_t x = 0; x < side; ++x) sum += rr[x], row[x] = below[x] + sum;
      else
        for (uint32_t x = 0; x < side; ++x) sum += rr[x], row[x] = sum;
    }
    storeFloats({q.data(), n, channels, step, shift}, at, side, hi, out.data());
  }
  // (A corrupt block has written values out of range before this throws; callers discard them.)
  if (hi > span) throw CodecError(std::string("corrupt ") + what + " block (value out of range)");
  return HeightQuantization(mode);
}

// ---- 8-bit samples (normals: x, y, z; colours: RGBA) ------------------------------------------

using Byte4 = std::array<uint8_t, 4>;

// The z byte of a unit normal with these x and y bytes (z >= 0), as packNormal rounds it.
const std::array<uint8_t, 65536>& unitZ() {
  static const std::array<uint8_t, 65536> table = [] {
    std::array<uint8_t, 65536> t{};
    for (int x = 0; x < 256; ++x)
      for (int y = 0; y < 256; ++y) {
        const double fx = x / 127.5 - 1.0, fy = y / 127.5 - 1.0;
        const double s = 1.0 - fx * fx - fy * fy;
        t[size_t(x) * 256 + size_t(y)] = uint8_t(std::lround((s > 0.0 ? std::sqrt(s) : 0.0) * 127.5 + 127.5));
      }
    return t;
  }();
  return table;
}

// The z prediction of a normal: unit length from its x and y, on the side (z above or below the
// middle) of its left neighbour (first column: below; first sample: above).
inline uint8_t predictZ(const uint8_t* b, uint32_t side, uint32_t x, uint32_t y, const std::array<uint8_t, 65536>& t) {
  const size_t i = (size_t(y) * side + x) * 4;
  const uint8_t up = t[size_t(b[i]) * 256 + b[i + 1]];
  const uint8_t nb = x > 0 ? b[i - 4 + 2] : y > 0 ? b[i - size_t(side) * 4 + 2] : 255;
  return nb >= 128 ? up : uint8_t(255 - up);
}

constexpr uint8_t kKindNormals = 0, kKindColours = 1;

// A kind of 8-bit block: its magic, its name in messages, its kind byte and its channels.
struct ByteBlockKind {
  const char (&magic)[4];
  const char* what;
  uint8_t kind;
  uint8_t channels;
};
constexpr ByteBlockKind kNormalBlocks{kNormalMagic, "normal", kKindNormals, 3};
constexpr ByteBlockKind kColourBlocks{kColourMagic, "colour", kKindColours, 4};

std::vector<uint8_t> encodeBytes(const ByteBlockKind& blocks, std::span<const Byte4> in, uint32_t side) {
  const uint8_t kind = blocks.kind, channels = blocks.channels;
  const size_t n = size_t(side) * side;
  if (side == 0 || in.size() != n) throw std::invalid_argument("encode: expected side^2 samples");
  const uint8_t* b = in.data()->data();
  std::vector<uint8_t> raw(kByteHeaderBytes + size_t(channels) * n);
  raw[0] = kind;
  raw[1] = channels;
  std::memcpy(raw.data() + 4, &side, 4);
  const auto& t = unitZ();
  for (uint32_t c = 0; c < channels; ++c) {
    uint8_t* plane = raw.data() + kByteHeaderBytes + size_t(c) * n;
    for (uint32_t y = 0; y < side; ++y)
      for (uint32_t x = 0; x < side; ++x) {
        const size_t s = size_t(y) * side + x;
        const uint8_t p =
            kind == kKindNormals && c == 2 ? predictZ(b, side, x, y, t) : predictByte(b + c, side, 4, x, y);
        plane[s] = zigzag8(uint8_t(b[s * 4 + c] - p));
      }
  }
  return frame(blocks.magic, raw);
}

// The body of an 8-bit block of `magic` (kind and channels in its header, `what` in messages),
// checked: `side` as the caller expects, exactly `expected` bytes. The thread's buffer (unframe).
const std::vector<uint8_t>& byteBody(std::span<const uint8_t> block, const char (&magic)[4], const char* what,
                                     const std::array<uint8_t, 2>& kindChannels, uint32_t side, size_t expected) {
  const std::vector<uint8_t>& raw = unframe(block, magic, what, kByteHeaderBytes, expected);
  uint32_t blockSide = 0;
  std::memcpy(&blockSide, raw.data() + 4, 4);
  if (raw[0] != kindChannels[0] || raw[1] != kindChannels[1])
    throw CodecError(std::string("corrupt ") + what + " block (header)");
  if (blockSide != side || raw.size() != expected)
    throw CodecError(std::string(what) + " block of side " + std::to_string(blockSide) + ", expected " +
                     std::to_string(side));
  return raw;
}

void decodeBytes(std::span<const uint8_t> block, const ByteBlockKind& blocks, uint32_t side, std::span<Byte4> out) {
  const char* what = blocks.what;
  const uint8_t kind = blocks.kind, channels = blocks.channels;
  const size_t n = size_t(side) * side;
  if (out.size() != n) throw std::invalid_argument(std::string("decode ") + what + ": output size");
  const std::vector<uint8_t>& raw =
      byteBody(block, blocks.magic, what, {kind, channels}, side, kByteHeaderBytes + size_t(channels) * n);
  uint8_t* b = out.data()->data();
  const auto& t = unitZ();
  const uint8_t* planes = raw.data() + kByteHeaderBytes;
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) {
      const size_t s = size_t(y) * side + x;
      // x and y (or R, G, B, A) first: the normal's z prediction reads this sample's x and y.
      for (uint32_t c = 0; c < channels; ++c) {
        if (kind == kKindNormals && c == 2) continue;
        b[s * 4 + c] = uint8_t(predictByte(b + c, side, 4, x, y) + unzigzag8(planes[size_t(c) * n + s]));
      }
      if (kind == kKindNormals) {
        b[s * 4 + 2] = uint8_t(predictZ(b, side, x, y, t) + unzigzag8(planes[2 * n + s]));
        b[s * 4 + 3] = 255;
      }
    }
}

}  // namespace

namespace {

// Each coordinate of side^2 positions at its nearest lattice point, in steps; `what` names the
// caller in the std::invalid_argument thrown for a wrong size, a bad step, a non-finite
// coordinate or one beyond 2^23 steps.
std::vector<int64_t> latticePoints(std::span<const float> xyz, uint32_t side, double step, const char* what) {
  const size_t n = size_t(side) * side;
  if (side == 0 || xyz.size() != 3 * n) throw std::invalid_argument(std::string(what) + ": expected 3 side^2 floats");
  if (!(step > 0.0) || !std::isfinite(step)) throw std::invalid_argument(std::string(what) + ": step must be > 0");
  std::vector<int64_t> q(3 * n);
  for (size_t i = 0; i < 3 * n; ++i) {
    if (!std::isfinite(xyz[i])) throw std::invalid_argument(std::string(what) + ": non-finite coordinate");
    const double v = std::nearbyint(double(xyz[i]) / step);
    if (std::abs(v) > double(kMaxSteps))
      throw std::invalid_argument(std::string(what) + ": a coordinate lies beyond 2^23 steps of the lattice");
    q[i] = int64_t(v);
  }
  return q;
}

}  // namespace

float quantizeToStep(float v, double step) { return float(std::nearbyint(double(v) / step) * step); }

std::vector<uint8_t> encodeHeights(std::span<const float> heights, uint32_t side, double precision) {
  const size_t n = size_t(side) * side;
  if (side == 0 || heights.size() != n) throw std::invalid_argument("encodeHeights: expected side^2 heights");
  bool integer = true;
  for (float h : heights) {
    if (!std::isfinite(h)) throw std::invalid_argument("encodeHeights: non-finite height");
    integer = integer && h == std::nearbyint(h) && std::abs(h) <= float(kMaxIntegerSteps);
  }
  const HeightQuantization mode = integer ? HeightQuantization::kInteger : HeightQuantization::kPrecision;
  if (!integer && !(precision > 0.0 && std::isfinite(precision)))
    throw std::invalid_argument("encodeHeights: non-integer heights need a precision > 0");
  const double step = integer ? 1.0 : precision;
  std::vector<int32_t> q(n);
  for (size_t i = 0; i < n; ++i) {
    const double v = std::nearbyint(double(heights[i]) / step);
    if (std::abs(v) > double(integer ? kMaxIntegerSteps : kMaxSteps))
      throw std::invalid_argument("encodeHeights: heights span more than 2^23 steps of the precision");
    q[i] = int32_t(v);
  }
  return encodeInts(kHeightBlocks, q, side, mode, step);
}

HeightQuantization blockQuantization(std::span<const uint8_t> block) {
  if (block.size() < kMagicBytes || std::memcmp(block.data(), kHeightMagic, kMagicBytes) != 0)
    throw CodecError("not a height block (bad magic)");
  // The header is the frame's first bytes: decode just those (the checksum is the decoder's).
  ZSTD_DCtx* d = decompressor();
  ZSTD_DCtx_reset(d, ZSTD_reset_session_only);
  uint8_t head[kIntHeaderBytes];
  ZSTD_outBuffer out{head, sizeof head, 0};
  ZSTD_inBuffer in{block.data() + kMagicBytes, block.size() - kMagicBytes, 0};
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
  decodeInts(block, kHeightBlocks, side, out);
}

std::vector<uint8_t> encodePositions(std::span<const float> xyz, uint32_t side, double step, int chartBorderSides,
                                     bool interpolated) {
  if (chartBorderSides > 15) throw std::invalid_argument("encodePositions: the chart border sides are 4 bits");
  const std::vector<int64_t> points = latticePoints(xyz, side, step, "encodePositions");
  const std::vector<int32_t> q(points.begin(), points.end());
  // Row order or, for a side of 2^k + 1, the interpolation order, whichever residuals take fewer
  // bits (one entropy coding, not two).
  std::vector<uint32_t> z = lorenzoResiduals(q, side, 3);
  IntBodyHeader h{HeightQuantization::kPrecision, step, side, 3, kFlagFirstSample};
  if (interpolated && interpolatedSide(side)) {
    std::vector<uint32_t> zi = interpolatedResiduals(q, side, 3);
    if (residualBits(zi) < residualBits(z)) z.swap(zi), h.flags |= kFlagInterpolated;
  }
  std::vector<uint8_t> all = frame(kPositionMagic, intBody(h, z, q.data()), kPositionLevel);
  if (chartBorderSides >= 0) {  // the planar squares' code where it is the smaller
    const std::vector<uint8_t> raw = planarBody(q, side, step, uint8_t(chartBorderSides));
    if (!raw.empty()) {
      std::vector<uint8_t> planar = frame(kPositionMagic, raw, kPositionLevel);
      if (planar.size() < all.size()) return planar;
    }
  }
  return all;
}

void decodePositions(std::span<const uint8_t> block, uint32_t side, std::span<float> out) {
  decodeInts(block, kPositionBlocks, side, out);
}

namespace {

// settlePositions' state: the input, the lattice points chosen so far, and those taken.
class PositionSettler {
 public:
  PositionSettler(std::span<const float> xyz, uint32_t side, double step, double tolerance)
      : xyz_(xyz),
        side_(side),
        step_(step),
        tolerance_(tolerance),
        q_(latticePoints(xyz, side, step, "settlePositions")) {
    taken_.reserve(size_t(side) * side);
    for (uint32_t y = 0; y < side; ++y)
      for (uint32_t x = 0; x < side; ++x)
        if (border(x, y)) taken_.insert(point(size_t(y) * side + x));
  }
  bool border(uint32_t x, uint32_t y) const { return x == 0 || y == 0 || x + 1 == side_ || y + 1 == side_; }

  // Settles sample (x, y), off the border, in forEachInterpolated's order (pass, spacing h).
  void settle(uint32_t x, uint32_t y, uint32_t h, int pass) {
    const size_t i = size_t(y) * side_ + x;
    // Per coordinate at most t / sqrt(3), so at most t in all.
    const double perCoordinate = 2.0 / (std::sqrt(3.0) * step_);
    const int64_t stride = int64_t(std::floor(std::min(tolerance_, windowDistance(x, y) / 4.0) * perCoordinate));
    const Point nearest{q_[3 * i], q_[3 * i + 1], q_[3 * i + 2]};
    if (stride > 1)
      for (int c = 0; c < 3; ++c) {
        const int64_t p =
            interpolatedValue(q_.data(), side_, 3, uint32_t(c), {x, y, h, pass});  // as the coder predicts
        const int64_t k = int64_t(std::nearbyint((double(xyz_[3 * i + c]) / step_ - double(p)) / double(stride)));
        const int64_t v = p + k * stride;
        if (std::abs(v) <= kMaxSteps) q_[3 * i + c] = v;
      }
    // No sample may meet another: the border samples (fixed at their nearest lattice points) and
    // every sample settled before it, anywhere in the image. On a densely sampled chart the
    // sample beside the border may round to the border's lattice point, and where a chart folds
    // back over itself, or its texels are barely a lattice step wide, samples farther apart in
    // the grid may too. Then its nearest lattice point, else the nearest free one beside it. Nor
    // may a centre (pass 3, the last corner of the four texels of spacing h round it) close a
    // triangle of no area (three samples on one line) in them.
    const auto blocked = [&](const Point& c) { return taken_.count(c) > 0 || (pass == 3 && flat(x, y, h, c)); };
    if (stride > 1 && blocked(point(i))) std::copy(nearest.begin(), nearest.end(), q_.begin() + 3 * i);
    for (int64_t r = 1; blocked(point(i)) && r <= kSettleReach; ++r) {
      // The free lattice points at Chebyshev distance r from the nearest, the closest to the input.
      double best = std::numeric_limits<double>::infinity();
      Point chosen = nearest;
      for (int64_t dz = -r; dz <= r; ++dz)
        for (int64_t dy = -r; dy <= r; ++dy)
          for (int64_t dx = -r; dx <= r; ++dx) {
            if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != r) continue;
            const Point c{nearest[0] + dx, nearest[1] + dy, nearest[2] + dz};
            if (blocked(c)) continue;
            double d2 = 0.0;
            for (int k = 0; k < 3; ++k) {
              const double e = double(c[k]) - double(xyz_[3 * i + k]) / step_;
              d2 += e * e;
            }
            if (d2 < best) best = d2, chosen = c;
          }
      std::copy(chosen.begin(), chosen.end(), q_.begin() + 3 * i);
    }
    taken_.insert(point(i));
  }

  std::vector<float> floats() const {
    std::vector<float> out(q_.size());
    for (size_t i = 0; i < q_.size(); ++i) out[i] = float(double(q_[i]) * step_);
    return out;
  }

 private:
  using Point = std::array<int64_t, 3>;
  struct PointHash {
    size_t operator()(const Point& c) const {
      uint64_t h = 0;
      for (int k = 0; k < 3; ++k) h = (h ^ uint64_t(c[k])) * 0x9E3779B97F4A7C15ull;
      return size_t(h ^ (h >> 29));
    }
  };
  Point point(size_t i) const { return Point{q_[3 * i], q_[3 * i + 1], q_[3 * i + 2]}; }

  // The input distance from sample (x, y) to the nearest other sample of its 5x5 grid window.
  double windowDistance(uint32_t x, uint32_t y) const {
    constexpr uint32_t kRing = 2;  // the window of grid neighbours kept apart: (2 kRing + 1)^2
    const size_t i = size_t(y) * side_ + x;
    const uint32_t x0 = x >= kRing ? x - kRing : 0, x1 = std::min(x + kRing, side_ - 1);
    const uint32_t y0 = y >= kRing ? y - kRing : 0, y1 = std::min(y + kRing, side_ - 1);
    double d = std::numeric_limits<double>::infinity();
    for (uint32_t v = y0; v <= y1; ++v)
      for (uint32_t u = x0; u <= x1; ++u) {
        if (u == x && v == y) continue;
        const size_t j = size_t(v) * side_ + u;
        const double dx = double(xyz_[3 * i]) - xyz_[3 * j], dy = double(xyz_[3 * i + 1]) - xyz_[3 * j + 1],
                     dz = double(xyz_[3 * i + 2]) - xyz_[3 * j + 2];
        d = std::min(d, std::sqrt(dx * dx + dy * dy + dz * dz));
      }
    return d;
  }

  // Whether c at centre (x, y) leaves a triangle of no area in one of the four texels of spacing h
  // round it (each split along its (0,0)-(1,1) diagonal, as the render grid draws it).
  bool flat(uint32_t x, uint32_t y, uint32_t h, const Point& c) const {
    const auto p = [&](uint32_t u, uint32_t v) { return u == x && v == y ? c : point(size_t(v) * side_ + u); };
    const auto line = [](const Point& a, const Point& b, const Point& d) {
      const int64_t ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
      const int64_t vx = d[0] - a[0], vy = d[1] - a[1], vz = d[2] - a[2];
      return uy * vz == uz * vy && uz * vx == ux * vz && ux * vy == uy * vx;
    };
    // c's triangles whose other two corners are apart (a border merged by its lattice is not c's).
    const auto closes = [&](const Point& a, const Point& b) { return a != b && line(a, b, c); };
    for (const uint32_t a : {x - h, x})
      for (const uint32_t b : {y - h, y}) {
        const Point p00 = p(a, b), p10 = p(a + h, b), p01 = p(a, b + h), p11 = p(a + h, b + h);
        const bool cornerX = a + h == x, cornerY = b + h == y;  // c is p1? / p?1
        if (cornerX == cornerY) {                               // p00 or p11: on the diagonal, in both triangles
          if (cornerX ? closes(p00, p10) || closes(p00, p01) : closes(p10, p11) || closes(p11, p01)) return true;
        } else if (closes(p00, p11)) {  // p10 or p01: in one triangle, with the diagonal
          return true;
        }
      }
    return false;
  }

  std::span<const float> xyz_;
  uint32_t side_;
  double step_, tolerance_;
  std::vector<int64_t> q_;
  std::unordered_set<Point, PointHash> taken_;  // the border's first, then each sample's as it is settled
};

}  // namespace

std::vector<float> settlePositions(std::span<const float> xyz, uint32_t side, double step, double tolerance) {
  if (!(tolerance >= 0.0) || !std::isfinite(tolerance))
    throw std::invalid_argument("settlePositions: the tolerance must be finite and >= 0");
  PositionSettler settler(xyz, side, step, tolerance);  // checks the sizes and the step
  if (side < 3) return settler.floats();                // every sample on the border
  if (!interpolatedSide(side)) throw std::invalid_argument("settlePositions: the side must be 2^k + 1");
  forEachInterpolated(side, [&](uint32_t x, uint32_t y, uint32_t h, int pass) {
    if (!settler.border(x, y)) settler.settle(x, y, h, pass);
  });
  return settler.floats();
}

namespace {

constexpr char kInterpolatedNormalMagic[4] = {'G', 'N', 'I', '1'};

// The interpolated prediction of byte c of sample (x, y) of a block of side `side` (4 bytes a
// sample) in forEachInterpolated's order: the rounded mean of the neighbours the pass names; a
// corner 128.
inline int interpolatedByte(const uint8_t* b, uint32_t side, uint32_t c, const OrderStep& o) {
  const uint32_t x = o.x, y = o.y, h = o.h;
  const auto at = [&](uint32_t u, uint32_t v) { return int(b[(size_t(v) * side + u) * 4 + c]); };
  switch (o.pass) {
    case 1: return (at(x - h, y) + at(x + h, y) + 1) >> 1;
    case 2: return (at(x, y - h) + at(x, y + h) + 1) >> 1;
    case 3: return (at(x - h, y) + at(x + h, y) + at(x, y - h) + at(x, y + h) + 2) >> 2;
    default: return 128;
  }
}

// The z prediction of a normal in that order: unit length from its x and y, on the side of the
// middle that the interpolated z is on.
inline int interpolatedZ(const uint8_t* b, uint32_t side, const OrderStep& o, const std::array<uint8_t, 65536>& t) {
  const uint32_t x = o.x, y = o.y;
  const size_t i = (size_t(y) * side + x) * 4;
  const int up = t[size_t(b[i]) * 256 + b[i + 1]];
  return interpolatedByte(b, side, 2, o) >= 128 ? up : 255 - up;
}

// Settles the normals of one block (origin (x0, y0) of an image `side` samples wide, `bs` = 2^k + 1
// samples a side) in forEachInterpolated's order: each byte off the block's border moves towards
// its prediction in multiples of 2 tolerance + 1, by at most the tolerance.
void settleInterpolatedBlock(uint8_t* image, uint32_t side, uint32_t x0, uint32_t y0, uint32_t bs, int tol) {
  thread_local std::vector<uint8_t> b;
  b.resize(size_t(bs) * bs * 4);
  for (uint32_t v = 0; v < bs; ++v)
    std::memcpy(b.data() + size_t(v) * bs * 4, image + (size_t(y0 + v) * side + x0) * 4, size_t(bs) * 4);
  const auto& t = unitZ();
  const int stride = 2 * tol + 1;
  const auto settle = [&](uint8_t& byte, int p) {
    const int v = byte, k = int(std::lround(double(v - p) / stride)), settled = p + k * stride;
    if (settled >= 0 && settled <= 255 && std::abs(settled - v) <= tol) byte = uint8_t(settled);
  };
  forEachInterpolated(bs, [&](uint32_t x, uint32_t y, uint32_t h, int pass) {
    if (x == 0 || y == 0 || x + 1 == bs || y + 1 == bs) return;
    uint8_t* s = b.data() + (size_t(y) * bs + x) * 4;
    for (uint32_t c = 0; c < 2; ++c) settle(s[c], interpolatedByte(b.data(), bs, c, {x, y, h, pass}));
    settle(s[2], interpolatedZ(b.data(), bs, {x, y, h, pass}, t));
  });
  for (uint32_t v = 0; v < bs; ++v)
    std::memcpy(image + (size_t(y0 + v) * side + x0) * 4, b.data() + size_t(v) * bs * 4, size_t(bs) * 4);
}

std::vector<uint8_t> encodeInterpolatedNormals(std::span<const Byte4> normals, uint32_t side) {
  const size_t n = size_t(side) * side;
  std::vector<uint8_t> raw(kByteHeaderBytes + 3 * n);
  raw[0] = kKindNormals;
  raw[1] = 3;
  std::memcpy(raw.data() + 4, &side, 4);
  const uint8_t* b = reinterpret_cast<const uint8_t*>(normals.data());
  uint8_t* planes = raw.data() + kByteHeaderBytes;
  const auto& t = unitZ();
  size_t k = 0;
  forEachInterpolated(side, [&](uint32_t x, uint32_t y, uint32_t h, int pass) {
    const size_t s = (size_t(y) * side + x) * 4;
    for (uint32_t c = 0; c < 2; ++c)
      planes[c * n + k] = zigzag8(uint8_t(b[s + c] - interpolatedByte(b, side, c, {x, y, h, pass})));
    planes[2 * n + k] = zigzag8(uint8_t(b[s + 2] - interpolatedZ(b, side, {x, y, h, pass}, t)));
    ++k;
  });
  return frame(kInterpolatedNormalMagic, raw);
}

void decodeInterpolatedNormals(std::span<const uint8_t> block, uint32_t side, std::span<Byte4> out) {
  const size_t n = size_t(side) * side;
  if (out.size() != n) throw std::invalid_argument("decode normal: output size");
  if (!interpolatedSide(side))
    throw CodecError("interpolated normal block for a side of " + std::to_string(side) + " (not 2^k + 1)");
  const std::vector<uint8_t>& raw =
      byteBody(block, kInterpolatedNormalMagic, "normal", {kKindNormals, 3}, side, kByteHeaderBytes + 3 * n);
  uint8_t* b = reinterpret_cast<uint8_t*>(out.data());
  const uint8_t* planes = raw.data() + kByteHeaderBytes;
  const auto& t = unitZ();
  size_t k = 0;
  forEachInterpolated(side, [&](uint32_t x, uint32_t y, uint32_t h, int pass) {
    const size_t s = (size_t(y) * side + x) * 4;
    for (uint32_t c = 0; c < 2; ++c)
      b[s + c] = uint8_t(interpolatedByte(b, side, c, {x, y, h, pass}) + unzigzag8(planes[c * n + k]));
    b[s + 2] = uint8_t(interpolatedZ(b, side, {x, y, h, pass}, t) + unzigzag8(planes[2 * n + k]));
    b[s + 3] = 255;
    ++k;
  });
}

}  // namespace

void settleNormals(std::span<Byte4> normals, uint32_t side, uint32_t tolerance, uint32_t blockIntervals) {
  if (!interpolatedSide(side) || normals.size() != size_t(side) * side)
    throw std::invalid_argument("settleNormals: expected side^2 normals, side 2^k + 1");
  if (!std::has_single_bit(blockIntervals))
    throw std::invalid_argument("settleNormals: blockIntervals must be a power of two");
  if (tolerance > 127) throw std::invalid_argument("settleNormals: a tolerance above 127 packed steps");
  if (tolerance == 0) return;
  const uint32_t B = std::min(blockIntervals, side - 1);
  if (B < 2) return;  // blocks of 2 samples a side: every sample on a border
  for (uint32_t y0 = 0; y0 + 1 < side; y0 += B)
    for (uint32_t x0 = 0; x0 + 1 < side; x0 += B)
      settleInterpolatedBlock(reinterpret_cast<uint8_t*>(normals.data()), side, x0, y0, B + 1, int(tolerance));
}

std::vector<uint8_t> encodeNormals(std::span<const Byte4> normals, uint32_t side) {
  for (const Byte4& nrm : normals)
    if (nrm[3] != 255) throw std::invalid_argument("encodeNormals: a packed normal's fourth byte is not 255");
  std::vector<uint8_t> lorenzo = encodeBytes(kNormalBlocks, normals, side);
  if (!interpolatedSide(side)) return lorenzo;
  std::vector<uint8_t> interpolated = encodeInterpolatedNormals(normals, side);
  return interpolated.size() < lorenzo.size() ? interpolated : lorenzo;
}

void decodeNormals(std::span<const uint8_t> block, uint32_t side, std::span<Byte4> out) {
  if (block.size() >= kMagicBytes && std::memcmp(block.data(), kInterpolatedNormalMagic, kMagicBytes) == 0)
    decodeInterpolatedNormals(block, side, out);
  else
    decodeBytes(block, kNormalBlocks, side, out);
}

namespace {

// The index of the k-th border sample in ring order (see encodeBorderNormals).
size_t borderSample(uint32_t side, uint32_t k) {
  const uint32_t m = side - 1;
  if (k < m) return k;                                         // first row, left to right
  if (k < 2 * m) return size_t(k - m) * side + m;              // last column, upwards
  if (k < 3 * m) return size_t(m) * side + (m - (k - 2 * m));  // last row, right to left
  return size_t(m - (k - 3 * m)) * side;                       // first column, downwards
}

}  // namespace

std::vector<uint8_t> encodeBorderNormals(std::span<const Byte4> normals, uint32_t side) {
  if (side < 2 || normals.size() != size_t(side) * side)
    throw std::invalid_argument("encodeBorderNormals: expected side^2 normals, side >= 2");
  const uint32_t ring = 4 * (side - 1);
  std::vector<uint8_t> raw(kByteHeaderBytes + 3 * size_t(ring));
  raw[0] = kKindNormals;
  raw[1] = 3;
  std::memcpy(raw.data() + 4, &side, 4);
  Byte4 prev{128, 128, 128, 255};
  for (uint32_t k = 0; k < ring; ++k) {
    const Byte4& nrm = normals[borderSample(side, k)];
    if (nrm[3] != 255) throw std::invalid_argument("encodeBorderNormals: a packed normal's fourth byte is not 255");
    for (uint32_t c = 0; c < 3; ++c) raw[kByteHeaderBytes + size_t(c) * ring + k] = zigzag8(uint8_t(nrm[c] - prev[c]));
    prev = nrm;
  }
  return frame(kBorderNormalMagic, raw);
}

void decodeBorderNormals(std::span<const uint8_t> block, uint32_t side, std::span<Byte4> out) {
  if (side < 2 || out.size() != size_t(side) * side)
    throw std::invalid_argument("decodeBorderNormals: expected side^2 normals, side >= 2");
  const uint32_t ring = 4 * (side - 1);
  const std::vector<uint8_t>& raw = byteBody(block, kBorderNormalMagic, "border normal", {kKindNormals, 3}, side,
                                             kByteHeaderBytes + 3 * size_t(ring));
  Byte4 prev{128, 128, 128, 255};
  for (uint32_t k = 0; k < ring; ++k) {
    Byte4& nrm = out[borderSample(side, k)];
    for (uint32_t c = 0; c < 3; ++c)
      nrm[c] = uint8_t(prev[c] + unzigzag8(raw[kByteHeaderBytes + size_t(c) * ring + k]));
    nrm[3] = 255;
    prev = nrm;
  }
}

std::vector<uint8_t> encodeColours(std::span<const Byte4> colours, uint32_t side) {
  return encodeBytes(kColourBlocks, colours, side);
}

void decodeColours(std::span<const uint8_t> block, uint32_t side, std::span<Byte4> out) {
  decodeBytes(block, kColourBlocks, side, out);
}

std::vector<uint8_t> compressBytes(std::span<const uint8_t> raw) { return frame(kBytesMagic, raw); }

std::vector<uint8_t> decompressBytes(std::span<const uint8_t> coded, size_t maxBytes) {
  if (coded.size() < kMagicBytes || std::memcmp(coded.data(), kBytesMagic, kMagicBytes) != 0)
    throw CodecError("not a compressed block (bad magic)");
  return decompressFrame(coded.subspan(kMagicBytes), maxBytes);
}

std::vector<uint8_t> compressFrame(std::span<const uint8_t> raw, int level) {
  const char none[4] = {};
  std::vector<uint8_t> out = frame(none, raw, level);
  out.erase(out.begin(), out.begin() + kMagicBytes);
  return out;
}

std::vector<uint8_t> decompressFrame(std::span<const uint8_t> coded, size_t maxBytes) {
  // Into a vector of its own (not unframe's buffer, which a thread keeps): a body may be large.
  const unsigned long long size = ZSTD_getFrameContentSize(coded.data(), coded.size());
  if (size == ZSTD_CONTENTSIZE_ERROR || size == ZSTD_CONTENTSIZE_UNKNOWN || size > maxBytes)
    throw CodecError("corrupt or truncated compressed block (frame header)");
  std::vector<uint8_t> raw(size);
  const size_t got = ZSTD_decompressDCtx(decompressor(), raw.data(), raw.size(), coded.data(), coded.size());
  if (ZSTD_isError(got) || got != size)
    throw CodecError(std::string("corrupt or truncated compressed block (") +
                     (ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short") + ")");
  return raw;
}

struct BytesCompressor::State {
  std::unique_ptr<ZSTD_CCtx, CCtxFree> cctx{ZSTD_createCCtx()};
  std::function<void(const uint8_t*, size_t)> sink;
  uint64_t total = 0, added = 0;
  std::vector<uint8_t> out = std::vector<uint8_t>(ZSTD_CStreamOutSize());
  bool finished = false;
};

BytesCompressor::BytesCompressor(uint64_t total, std::function<void(const uint8_t*, size_t)> sink)
    : state_(std::make_unique<State>()) {
  State& s = *state_;
  if (!s.cctx) throw std::runtime_error("block codec: cannot create a zstd context");
  s.sink = std::move(sink);
  s.total = total;
  ZSTD_CCtx_setParameter(s.cctx.get(), ZSTD_c_compressionLevel, kLevel);
  ZSTD_CCtx_setParameter(s.cctx.get(), ZSTD_c_checksumFlag, 1);
  ZSTD_CCtx_setPledgedSrcSize(s.cctx.get(), total);  // the frame header states the size
  s.sink(reinterpret_cast<const uint8_t*>(kBytesMagic), kMagicBytes);
}

BytesCompressor::~BytesCompressor() = default;

void BytesCompressor::drive(std::span<const uint8_t> piece, bool end) {
  State& s = *state_;
  ZSTD_inBuffer in{piece.data(), piece.size(), 0};
  for (;;) {
    ZSTD_outBuffer out{s.out.data(), s.out.size(), 0};
    const size_t left = ZSTD_compressStream2(s.cctx.get(), &out, &in, end ? ZSTD_e_end : ZSTD_e_continue);
    if (ZSTD_isError(left)) throw std::runtime_error(std::string("block codec: zstd: ") + ZSTD_getErrorName(left));
    if (out.pos > 0) s.sink(s.out.data(), out.pos);
    if (end ? left == 0 : in.pos == in.size) break;
  }
}

void BytesCompressor::add(std::span<const uint8_t> piece) {
  State& s = *state_;
  if (s.finished || s.added + piece.size() > s.total) throw std::logic_error("BytesCompressor: more bytes than stated");
  s.added += piece.size();
  drive(piece, false);
}

void BytesCompressor::finish() {
  State& s = *state_;
  if (s.finished || s.added != s.total) throw std::logic_error("BytesCompressor: fewer bytes than stated");
  s.finished = true;
  drive({}, true);
}

}  // namespace gimlod
