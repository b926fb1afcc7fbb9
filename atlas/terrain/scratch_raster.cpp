#include "atlas/terrain/scratch_raster.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include <fcntl.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include "core/atlas_format.h"
#include "core/block_codec.h"

namespace gimlod {

namespace fs = std::filesystem;

namespace {

constexpr size_t kHeaderBytes = 16;  // mode, planes, validity, 0, tile width, tile height, 0
enum Mode : uint8_t { kIntegers = 0, kOrderedFloats = 1 };
enum Validity : uint8_t { kAllValid = 0, kAllVoid = 1, kMixed = 2 };
constexpr float kMaxInteger = 16777216.f;  // 2^24: every integer up to it is a float

inline uint32_t zigzag(uint32_t r) { return (r << 1) ^ uint32_t(int32_t(r) >> 31); }
inline uint32_t unzigzag(uint32_t z) { return (z >> 1) ^ (0u - (z & 1)); }

void put32(uint8_t* p, uint32_t v) { std::memcpy(p, &v, 4); }
uint32_t get32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

// A float's bits as an integer that orders as the floats do (-0 just below +0): within a binade
// it is the value in units of the last place, so smooth heights have small differences.
inline uint32_t ordered(float x) {
  const uint32_t b = std::bit_cast<uint32_t>(x);
  return b & 0x80000000u ? ~(b & 0x7fffffffu) : b;
}
inline float unordered(uint32_t o) {
  return std::bit_cast<float>(int32_t(o) < 0 ? (~o & 0x7fffffffu) | 0x80000000u : o);
}

// The Lorenzo prediction of sample (x, y) of a w-wide tile from those before it, modulo 2^32.
inline uint32_t predict(const uint32_t* q, uint32_t w, uint32_t x, uint32_t y) {
  const size_t i = size_t(y) * w + x;
  if (y == 0) return x == 0 ? 0 : q[i - 1];
  if (x == 0) return q[i - w];
  return q[i - 1] + q[i - w] - q[i - w - 1];
}

std::vector<uint8_t> encodeTile(const float* h, const uint8_t* v, uint32_t w, uint32_t hgt, uint8_t* validity) {
  const size_t n = size_t(w) * hgt;
  const size_t valid = size_t(std::count_if(v, v + n, [](uint8_t o) { return o != 0; }));
  *validity = valid == n ? kAllValid : valid == 0 ? kAllVoid : kMixed;
  const bool integers = std::all_of(h, h + n, [](float x) {
    return x == std::nearbyint(x) && std::abs(x) <= kMaxInteger && !(x == 0.f && std::signbit(x));
  });
  std::vector<uint32_t> q(n), z(n);
  for (size_t i = 0; i < n; ++i) q[i] = integers ? uint32_t(int32_t(h[i])) : ordered(h[i]);
  for (uint32_t y = 0; y < hgt; ++y)
    for (uint32_t x = 0; x < w; ++x) z[size_t(y) * w + x] = zigzag(q[size_t(y) * w + x] - predict(q.data(), w, x, y));
  uint32_t all = 0;
  for (uint32_t r : z) all |= r;
  uint8_t planes = 0;
  while (planes < 4 && (all >> (8 * planes)) != 0) ++planes;
  std::vector<uint8_t> raw(kHeaderBytes + size_t(planes) * n + (*validity == kMixed ? n : 0));
  raw[0] = integers ? kIntegers : kOrderedFloats;
  raw[1] = planes;
  raw[2] = *validity;
  put32(raw.data() + 4, w);
  put32(raw.data() + 8, hgt);
  for (uint8_t p = 0; p < planes; ++p) {
    uint8_t* plane = raw.data() + kHeaderBytes + size_t(p) * n;
    for (size_t i = 0; i < n; ++i) plane[i] = uint8_t(z[i] >> (8 * p));
  }
  if (*validity == kMixed) {
    uint8_t* plane = raw.data() + kHeaderBytes + size_t(planes) * n;
    for (size_t i = 0; i < n; ++i) plane[i] = v[i] ? 1 : 0;
  }
  return compressBytes(raw);
}

// Decodes a tile made by encodeTile; throws CodecError when it is not one of w x hgt samples.
void decodeTile(std::span<const uint8_t> coded, uint32_t w, uint32_t hgt, float* h, uint8_t* v) {
  const size_t n = size_t(w) * hgt;
  const std::vector<uint8_t> raw = decompressBytes(coded, kHeaderBytes + 5 * n);
  if (raw.size() < kHeaderBytes || raw[0] > kOrderedFloats || raw[1] > 4 || raw[2] > kMixed ||
      get32(raw.data() + 4) != w || get32(raw.data() + 8) != hgt ||
      raw.size() != kHeaderBytes + size_t(raw[1]) * n + (raw[2] == kMixed ? n : 0))
    throw CodecError("not a scratch tile of " + std::to_string(w) + " x " + std::to_string(hgt) + " samples");
  const uint8_t planes = raw[1];
  std::vector<uint32_t> z(n, 0);
  for (uint8_t p = 0; p < planes; ++p) {
    const uint8_t* plane = raw.data() + kHeaderBytes + size_t(p) * n;
    for (size_t i = 0; i < n; ++i) z[i] |= uint32_t(plane[i]) << (8 * p);
  }
  std::vector<uint32_t> q(n);
  for (uint32_t y = 0; y < hgt; ++y)
    for (uint32_t x = 0; x < w; ++x) q[size_t(y) * w + x] = predict(q.data(), w, x, y) + unzigzag(z[size_t(y) * w + x]);
  if (raw[0] == kIntegers) {
    for (size_t i = 0; i < n; ++i) {
      if (int32_t(q[i]) < -int32_t(kMaxInteger) || int32_t(q[i]) > int32_t(kMaxInteger))
        throw CodecError("scratch tile: an integer out of range");
      h[i] = float(int32_t(q[i]));
    }
  } else {
    for (size_t i = 0; i < n; ++i) h[i] = unordered(q[i]);
  }
  if (raw[2] == kMixed)
    std::memcpy(v, raw.data() + kHeaderBytes + size_t(planes) * n, n);
  else
    std::fill_n(v, n, raw[2] == kAllValid ? 1 : 0);
}

// The overlap of two windows.
CellWindow overlap(const CellWindow& a, const CellWindow& b) {
  return {std::max(a.x0, b.x0), std::max(a.y0, b.y0), std::min(a.x1, b.x1), std::min(a.y1, b.y1)};
}

// Copies the samples of o (inside both windows) from a row-major image of window a to one of b.
template <typename T>
void copyOverlap(const T* from, const CellWindow& a, T* to, const CellWindow& b, const CellWindow& o) {
  for (int64_t y = o.y0; y < o.y1; ++y)
    std::copy_n(from + size_t(y - a.y0) * size_t(a.width()) + size_t(o.x0 - a.x0), o.width(),
                to + size_t(y - b.y0) * size_t(b.width()) + size_t(o.x0 - b.x0));
}

}  // namespace

struct ScratchRaster::Decoded {
  std::vector<float> h;
  std::vector<uint8_t> v;
};

ScratchRaster::ScratchRaster(fs::path file, fs::path dem, uint64_t width, uint64_t height, uint32_t tile)
    : path_(std::move(file)), dem_(std::move(dem)), width_(width), height_(height), tile_(tile) {
  if (width == 0 || height == 0) throw std::invalid_argument("ScratchRaster: an empty raster");
  if (tile < 8 || tile > 4096) throw std::invalid_argument("ScratchRaster: tile side outside 8..4096");
  tilesX_ = (width + tile - 1) / tile;
  tilesY_ = (height + tile - 1) / tile;
  tiles_.resize(size_t(tilesX_ * tilesY_));
  fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd_ < 0) fail(std::string("cannot create the scratch file (") + std::strerror(errno) + ")");
}

namespace {

// The index of a kept raster: a magic, the raster's size and tile side, then each tile's entry.
constexpr char kIndexMagic[8] = {'G', 'L', 'S', 'C', 'R', 'X', '0', '1'};

}  // namespace

ScratchRaster::ScratchRaster(fs::path file, fs::path dem, const fs::path& indexFile)
    : path_(std::move(file)), dem_(std::move(dem)), width_(0), height_(0), tile_(0), kept_(true), readOnly_(true) {
  const std::vector<uint8_t> bytes = readFileBytes(indexFile);
  auto damaged = [&](const std::string& what) {
    throw InputError(dem_.string() + ": scratch index " + indexFile.string() + ": " + what);
  };
  size_t at = 0;
  auto take = [&](void* out, size_t n) {
    if (bytes.size() - at < n) damaged("truncated");
    std::memcpy(out, bytes.data() + at, n);
    at += n;
  };
  char magic[8];
  take(magic, 8);
  if (std::memcmp(magic, kIndexMagic, 8) != 0) damaged("not a scratch index");
  uint64_t end = 0;
  take(&width_, 8);
  take(&height_, 8);
  take(&tile_, 4);
  take(&end, 8);
  if (width_ == 0 || height_ == 0 || width_ > (uint64_t{1} << 32) || height_ > (uint64_t{1} << 32) || tile_ < 8 ||
      tile_ > 4096)
    damaged("impossible raster size");
  tilesX_ = (width_ + tile_ - 1) / tile_;
  tilesY_ = (height_ + tile_ - 1) / tile_;
  const size_t entry = 8 + 4 + 1;
  if (bytes.size() - at != tilesX_ * tilesY_ * entry) damaged("the tiles' entries do not match the raster's size");
  tiles_.resize(size_t(tilesX_ * tilesY_));
  for (Tile& t : tiles_) {
    take(&t.offset, 8);
    take(&t.bytes, 4);
    take(&t.validity, 1);
    if (t.validity > kMixed || t.offset + t.bytes > end) damaged("a tile lies past the file's end");
  }
  end_ = end;
  fd_ = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) fail(std::string("cannot open the scratch file (") + std::strerror(errno) + ")");
  const off_t size = ::lseek(fd_, 0, SEEK_END);
  if (size < 0 || uint64_t(size) < end_) fail("shorter than its index says (damaged or truncated)");
}

ScratchRaster::~ScratchRaster() {
  if (fd_ >= 0) ::close(fd_);
  if (kept_) return;
  std::error_code ec;
  fs::remove(path_, ec);
}

void ScratchRaster::keep(const fs::path& indexFile) {
  if (readOnly_) throw std::logic_error("ScratchRaster::keep: the raster is read-only");
  if (::fsync(fd_) != 0) fail(std::string("cannot flush it (") + std::strerror(errno) + ")");
  std::vector<uint8_t> out(kIndexMagic, kIndexMagic + 8);
  auto put = [&](const void* p, size_t n) { out.insert(out.end(), (const uint8_t*)p, (const uint8_t*)p + n); };
  const std::lock_guard lock(mutex_);
  put(&width_, 8);
  put(&height_, 8);
  put(&tile_, 4);
  put(&end_, 8);
  for (const Tile& t : tiles_) {
    put(&t.offset, 8);
    put(&t.bytes, 4);
    put(&t.validity, 1);
  }
  atomicWriteFile(indexFile, out.data(), out.size());
  kept_ = true;
}

void ScratchRaster::fail(const std::string& what) const {
  throw InputError(dem_.string() + ": scratch raster " + path_.string() + ": " + what);
}

void ScratchRaster::check(const CellWindow& w, const char* what) const {
  if (w.empty() || w.x0 < 0 || w.y0 < 0 || uint64_t(w.x1) > width_ || uint64_t(w.y1) > height_)
    throw std::invalid_argument(std::string("ScratchRaster::") + what + ": a window outside the raster");
}

CellWindow ScratchRaster::tileWindow(uint64_t t) const {
  const int64_t tx = int64_t(t % tilesX_), ty = int64_t(t / tilesX_), s = tile_;
  return {tx * s, ty * s, std::min<int64_t>((tx + 1) * s, int64_t(width_)),
          std::min<int64_t>((ty + 1) * s, int64_t(height_))};
}

std::vector<uint64_t> ScratchRaster::tilesOf(const CellWindow& w) const {
  std::vector<uint64_t> out;
  for (uint64_t ty = uint64_t(w.y0) / tile_; ty <= uint64_t(w.y1 - 1) / tile_; ++ty)
    for (uint64_t tx = uint64_t(w.x0) / tile_; tx <= uint64_t(w.x1 - 1) / tile_; ++tx) out.push_back(ty * tilesX_ + tx);
  return out;
}

void ScratchRaster::forEachTile(const CellWindow& w, const TileVisit& visit) const {
  const std::vector<uint64_t> tiles = tilesOf(w);
  tbb::parallel_for(size_t{0}, tiles.size(), [&](size_t k) {
    const CellWindow tw = tileWindow(tiles[k]);
    visit(tiles[k], tw, overlap(w, tw));
  });
}

void ScratchRaster::decode(uint64_t t, Decoded& out) const {
  const CellWindow tw = tileWindow(t);
  const size_t n = tw.cells();
  out.h.resize(n);
  out.v.resize(n);
  Tile entry;
  {
    const std::lock_guard lock(mutex_);
    entry = tiles_[t];
  }
  if (entry.bytes == 0) {
    std::fill(out.h.begin(), out.h.end(), 0.f);
    std::fill(out.v.begin(), out.v.end(), uint8_t{0});
    return;
  }
  std::vector<uint8_t> coded(entry.bytes);
  size_t got = 0;
  while (got < coded.size()) {
    const ssize_t r = ::pread(fd_, coded.data() + got, coded.size() - got, off_t(entry.offset + got));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0)
      fail("tile " + std::to_string(t) + ": cannot read it (" + (r < 0 ? std::strerror(errno) : "short") + ")");
    got += size_t(r);
  }
  try {
    decodeTile(coded, uint32_t(tw.width()), uint32_t(tw.height()), out.h.data(), out.v.data());
  } catch (const CodecError& e) {
    fail("tile " + std::to_string(t) + " is damaged: " + e.what());
  }
}

void ScratchRaster::write(const CellWindow& w, const float* heights, const uint8_t* valid) {
  check(w, "write");
  if (readOnly_) throw std::logic_error("ScratchRaster::write: the raster was opened read-only");
  forEachTile(w, [&](uint64_t t, const CellWindow& tw, const CellWindow& o) {
    Decoded d;
    if (valid && o.x0 == tw.x0 && o.y0 == tw.y0 && o.x1 == tw.x1 && o.y1 == tw.y1) {
      d.h.resize(tw.cells());
      d.v.resize(tw.cells());
    } else {
      decode(t, d);
    }
    copyOverlap(heights, w, d.h.data(), tw, o);
    if (valid) copyOverlap(valid, w, d.v.data(), tw, o);
    uint8_t validity = 0;
    const std::vector<uint8_t> coded =
        encodeTile(d.h.data(), d.v.data(), uint32_t(tw.width()), uint32_t(tw.height()), &validity);
    const std::lock_guard lock(mutex_);
    const uint64_t at = end_;
    size_t put = 0;
    while (put < coded.size()) {
      const ssize_t r = ::pwrite(fd_, coded.data() + put, coded.size() - put, off_t(at + put));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) fail(std::string("cannot write it (") + (r < 0 ? std::strerror(errno) : "short") + "; disk full?)");
      put += size_t(r);
    }
    end_ += coded.size();
    Tile& entry = tiles_[t];
    if (entry.bytes > 0) {
      // The old version's whole pages go back to the file system; where it cannot, they stay.
      (void)::fallocate(fd_, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE, off_t(entry.offset), off_t(entry.bytes));
      live_ -= entry.bytes;
    }
    entry = Tile{at, uint32_t(coded.size()), validity};
    live_ += coded.size();
    peak_ = std::max(peak_, live_);
  });
}

void ScratchRaster::read(const CellWindow& w, float* heights, uint8_t* valid) const {
  check(w, "read");
  forEachTile(w, [&](uint64_t t, const CellWindow& tw, const CellWindow& o) {
    Decoded d;
    decode(t, d);
    if (heights) copyOverlap(d.h.data(), tw, heights, w, o);
    if (valid) copyOverlap(d.v.data(), tw, valid, w, o);
  });
}

bool ScratchRaster::hasVoids(const CellWindow& w) const {
  check(w, "hasVoids");
  for (uint64_t t : tilesOf(w)) {
    Tile entry;
    {
      const std::lock_guard lock(mutex_);
      entry = tiles_[t];
    }
    if (entry.bytes == 0 || entry.validity == kAllVoid) return true;
    if (entry.validity == kAllValid) continue;
    Decoded d;
    decode(t, d);
    const CellWindow tw = tileWindow(t), o = overlap(w, tw);
    for (int64_t y = o.y0; y < o.y1; ++y) {
      const uint8_t* row = d.v.data() + size_t(y - tw.y0) * size_t(tw.width()) + size_t(o.x0 - tw.x0);
      if (std::find(row, row + o.width(), uint8_t{0}) != row + o.width()) return true;
    }
  }
  return false;
}

uint64_t ScratchRaster::liveBytes() const {
  const std::lock_guard lock(mutex_);
  return live_;
}

uint64_t ScratchRaster::peakBytes() const {
  const std::lock_guard lock(mutex_);
  return peak_;
}

}  // namespace gimlod
