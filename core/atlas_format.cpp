// On-disk atlas format: manifest (JSON), block-structured chart pyramid files, atomic writes.
// Based on: Niski, Purnomo, Cohen, "Multi-grained Level of Detail Using a Hierarchical Seamless
// Texture Atlas", I3D 2007, section 6 (paging charts in blocks of the maximum node resolution).
#include "core/atlas_format.h"
#include "core/block_codec.h"
#include "core/vector_clones.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <fcntl.h>
#include <limits>
#include <mutex>
#include <random>
#include <unistd.h>

#include <nlohmann/json.hpp>

namespace gimlod {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// An option reference: kOptionOpen + parameter name + kOptionClose (control characters that no
// message text holds).
constexpr char kOptionOpen = '\x1e';
constexpr char kOptionClose = '\x1f';

std::string spellOptions(const std::string& marked, const std::function<std::string(std::string_view)>& spell) {
  std::string out;
  out.reserve(marked.size());
  size_t i = 0;
  while (i < marked.size()) {
    const size_t open = marked.find(kOptionOpen, i);
    const size_t close = open == std::string::npos ? open : marked.find(kOptionClose, open + 1);
    if (close == std::string::npos) {
      out.append(marked, i, std::string::npos);
      break;
    }
    out.append(marked, i, open - i);
    out += spell(std::string_view(marked).substr(open + 1, close - open - 1));
    i = close + 1;
  }
  return out;
}

}  // namespace

InputError::InputError(const std::string& message)
    : std::runtime_error(spellOptions(message, [](std::string_view name) { return std::string(name); })),
      marked_(message) {}

std::string InputError::message(const std::function<std::string(std::string_view)>& spell) const {
  return spellOptions(marked_, spell);
}

std::string optionRef(std::string_view name) {
  std::string s(1, kOptionOpen);
  s += name;
  s += kOptionClose;
  return s;
}

const char* atlasKindName(AtlasKind kind) {
  switch (kind) {
    case AtlasKind::Heightfield: return "heightfield";
    case AtlasKind::Geometry: return "geometry";
  }
  return "?";
}

namespace {

constexpr const char* kFormatTag = "gimlod-atlas";
constexpr char kChartMagic[4] = {'G', 'L', 'M', 'C'};
constexpr uint32_t kChartFileVersion = 1;          // heights + normals
constexpr uint32_t kChartFileVersionChannels = 2;  // any channels, with a channel mask
constexpr uint32_t kChartFileVersionCoded = 3;     // any channels, each block coded
constexpr size_t kChartHeaderBytes = 4 + 4 * 4;
constexpr size_t kChartHeaderBytesV2 = kChartHeaderBytes + 4;
constexpr size_t kDirEntryBytes = 16;                            // version 1
constexpr size_t kCodedEntryBytes = 12;                          // version 3, per channel: u64 offset, u32 bytes
constexpr size_t kChartHeaderBytesV3 = kChartHeaderBytesV2 + 4;  // + u32 flags
constexpr size_t kFrameBytes = 4 * 8 + 2 * 8;                    // HeightFieldFrame
constexpr uint32_t kFlagDerivedNormals = 1;
constexpr uint32_t kFlagBorderNormals = 2;     // geometry: normals of block borders stored, the rest derived
constexpr uint32_t kFlagWrapColumns = 4;       // with derived normals: the frame's columns circle a planet
constexpr uint32_t kFlagSubsampledLevels = 8;  // geometry: levels past the first one-block level not stored
constexpr size_t kChannelBytes[kChannelCount] = {sizeof(float), sizeof(PackedNormal), 3 * sizeof(float),
                                                 sizeof(PackedColour)};
constexpr bool kChannelIsFloat[kChannelCount] = {true, false, true, false};
constexpr uint32_t kHeightFieldMask = (1u << kChannelHeights) | (1u << kChannelNormals);
constexpr uint32_t kAttributeMask = 1u << kChannelColours;  // an attribute chart: colours alone

std::string quoted(const fs::path& p) { return p.string(); }  // path as shown in messages

// ---- little-endian helpers ----------------------------------------------------------------

template <typename T>
T toLittle(T v) {
  if constexpr (std::endian::native == std::endian::big) {
    auto bytes = std::bit_cast<std::array<uint8_t, sizeof(T)>>(v);
    std::reverse(bytes.begin(), bytes.end());
    return std::bit_cast<T>(bytes);
  } else {
    return v;
  }
}

template <typename T>
void putLe(std::vector<uint8_t>& buf, size_t at, T v) {
  v = toLittle(v);
  std::memcpy(buf.data() + at, &v, sizeof(T));
}

template <typename T>
T getLe(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return toLittle(v);
}

// Converts an array of little-endian floats in place to native order (no-op on little-endian).
void floatsFromLe(float* p, size_t n) {
  if constexpr (std::endian::native == std::endian::big) {
    for (size_t i = 0; i < n; ++i) p[i] = toLittle(p[i]);
  }
}

uint32_t log2Exact(uint32_t v) { return static_cast<uint32_t>(std::countr_zero(v)); }

// ---- manifest JSON helpers ------------------------------------------------------------------

struct JsonReader {
  const fs::path& file;

  [[noreturn]] void fail(const std::string& what) const { throw InputError(quoted(file) + ": " + what); }
  const json& field(const json& j, const char* key, const std::string& ctx) const {
    auto it = j.find(key);
    if (it == j.end()) fail("missing field '" + ctx + key + "'");
    return *it;
  }
  int64_t integer(const json& v, const std::string& name, int64_t lo, int64_t hi) const {
    if (!v.is_number_integer()) fail("field '" + name + "' must be an integer");
    int64_t x;
    if (v.is_number_unsigned()) {
      uint64_t u = v.get<uint64_t>();
      if (u > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) fail("field '" + name + "' is out of range");
      x = static_cast<int64_t>(u);
    } else {
      x = v.get<int64_t>();
    }
    if (x < lo || x > hi)
      fail("field '" + name + "' = " + std::to_string(x) + " is out of range [" + std::to_string(lo) + ", " +
           std::to_string(hi) + "]");
    return x;
  }
  uint32_t u32(const json& j, const char* key, const std::string& ctx = "") const {
    return static_cast<uint32_t>(integer(field(j, key, ctx), ctx + key, 0, std::numeric_limits<uint32_t>::max()));
  }
  uint64_t u64(const json& v, const std::string& name) const {
    if (!v.is_number_unsigned() && !(v.is_number_integer() && v.get<int64_t>() >= 0))
      fail("field '" + name + "' must be a non-negative integer");
    return v.get<uint64_t>();
  }
  double number(const json& v, const std::string& name) const {
    if (!v.is_number()) fail("field '" + name + "' must be a number");
    double d = v.get<double>();
    if (!std::isfinite(d)) fail("field '" + name + "' must be finite");
    return d;
  }
  std::string string(const json& v, const std::string& name) const {
    if (!v.is_string()) fail("field '" + name + "' must be a string");
    return v.get<std::string>();
  }
  bool boolean(const json& v, const std::string& name) const {
    if (!v.is_boolean()) fail("field '" + name + "' must be true or false");
    return v.get<bool>();
  }
  template <size_t N>
  std::array<double, N> numbers(const json& v, const std::string& name) const {
    if (!v.is_array() || v.size() != N)
      fail("field '" + name + "' must be an array of " + std::to_string(N) + " numbers");
    std::array<double, N> out{};
    for (size_t i = 0; i < N; ++i) out[i] = number(v[i], name + "[" + std::to_string(i) + "]");
    return out;
  }
};

nlohmann::ordered_json toJson(const RootNeighbour& n) {
  // "reversed" is written only where it is not the default (true), as no writer makes it: a
  // manifest of many charts is a quarter smaller.
  nlohmann::ordered_json j{{"chart", n.chart}, {"edge", n.edge}};
  if (!n.reversed) j["reversed"] = false;
  return j;
}

}  // namespace

// ---- small shared helpers ---------------------------------------------------------------------

bool isChartSizeValid(uint32_t n) { return n >= 3 && n <= 65537 && std::has_single_bit(n - 1); }

PackedNormal packNormal(float x, float y, float z) {
  auto q = [](float c) -> uint8_t {
    if (!(c == c)) c = 0.f;  // NaN -> 0
    c = std::clamp(c, -1.f, 1.f);
    return static_cast<uint8_t>(std::lround(c * 127.5f + 127.5f));
  };
  return PackedNormal{q(x), q(y), q(z), 255};
}

std::array<float, 3> unpackNormal(const PackedNormal& n) {
  return {n[0] / 127.5f - 1.f, n[1] / 127.5f - 1.f, n[2] / 127.5f - 1.f};
}

GIMLOD_VECTOR_CLONES
void geometryImageNormals(const float* xyz, uint32_t side, PackedNormal* out) {
  const size_t row = 3 * size_t(side), n = size_t(side) * side;
  // The normal of the differences a (along u) and b (along v), packed; false where it vanishes.
  // note: single precision and a truncating quantizer, as heightFieldNormals: this runs on the
  // loader thread for every page of such an atlas.
  auto pack = [](const float* a, const float* b, PackedNormal& o) {
    const float c[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    const float l2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
    if (!(l2 > 0.f) || !std::isfinite(l2)) return false;
    const float s = 127.5f / std::sqrt(l2);
    for (int k = 0; k < 3; ++k) o[k] = uint8_t(std::clamp(c[k] * s + 127.5f, 0.f, 255.f) + 0.5f);
    o[3] = 255;
    return true;
  };
  // Samples 2 or more from the border first: the differences over 2 and 4 intervals summed,
  // smoother than over 2 alone where the input's triangles span a few samples. Channel by channel,
  // in a vector loop per row: the arithmetic of pack, the clamp in integers after the truncation
  // (the same bytes: c s lies within 127.5 of 0). Where the cross product vanishes (or is not
  // finite) the row gets 0, which no packed normal is (its fourth byte is 255), and the sample
  // goes on below.
  static_assert(std::endian::native == std::endian::little, "a packed normal's bytes as one 32-bit word");
  thread_local std::vector<float> channels;
  thread_local std::vector<uint32_t> packedRow;
  channels.resize(3 * n);
  packedRow.resize(side);
  float *X = channels.data(), *Y = X + n, *Z = Y + n;
  for (size_t i = 0; i < n; ++i) X[i] = xyz[3 * i], Y[i] = xyz[3 * i + 1], Z[i] = xyz[3 * i + 2];
  auto placed = [&](uint32_t u, uint32_t v) {
    return u >= 2 && v >= 2 && u + 2 < side && v + 2 < side && out[size_t(v) * side + u][3] == 255;
  };
  for (uint32_t v = 2; v + 2 < side; ++v) {
    const size_t at = size_t(v) * side, s1 = side, s2 = 2 * size_t(side);
    uint32_t* o = packedRow.data();
    for (uint32_t u = 2; u + 2 < side; ++u) {
      const size_t i = at + u;
      const float ax = X[i + 1] - X[i - 1] + X[i + 2] - X[i - 2], bx = X[i + s1] - X[i - s1] + X[i + s2] - X[i - s2];
      const float ay = Y[i + 1] - Y[i - 1] + Y[i + 2] - Y[i - 2], by = Y[i + s1] - Y[i - s1] + Y[i + s2] - Y[i - s2];
      const float az = Z[i + 1] - Z[i - 1] + Z[i + 2] - Z[i - 2], bz = Z[i + s1] - Z[i - s1] + Z[i + s2] - Z[i - s2];
      const float cx = ay * bz - az * by, cy = az * bx - ax * bz, cz = ax * by - ay * bx;
      const uint32_t l2 = std::bit_cast<uint32_t>(cx * cx + cy * cy + cz * cz);
      const uint32_t good = 0u - uint32_t(l2 - 1u < 0x7f7fffffu);  // > 0 and finite: all ones
      const float s = 127.5f / std::sqrt(std::bit_cast<float>((l2 & good) | (0x3f800000u & ~good)));  // else 1
      auto q = [&](float c) {
        const int32_t t = int32_t(std::bit_cast<float>(std::bit_cast<uint32_t>(c) & good) * s + 127.5f + 0.5f);
        return uint32_t(std::clamp(t, 0, 255));
      };
      o[u] = (q(cx) | q(cy) << 8 | q(cz) << 16 | 0xff000000u) & good;  // a PackedNormal's bytes, in order
    }
    if (side > 4) std::memcpy(out + at + 2, o + 2, (size_t(side) - 4) * sizeof(uint32_t));
  }
  for (uint32_t v = 1; v + 1 < side; ++v) {
    const float* p = xyz + v * row;
    for (uint32_t u = 1; u + 1 < side; ++u) {
      if (placed(u, v)) continue;
      const float* q = p + 3 * size_t(u);
      const float *l = q - 3, *r = q + 3, *d = q - row, *t = q + row;
      float a[3], b[3];
      PackedNormal& o = out[size_t(v) * side + u];
      for (int k = 0; k < 3; ++k) a[k] = r[k] - l[k], b[k] = t[k] - d[k];
      if (pack(a, b, o)) continue;
      // One-sided differences where the central ones vanish.
      const float* pairs[4][4] = {{r, q, t, q}, {q, l, t, q}, {q, l, q, d}, {r, q, q, d}};
      bool done = false;
      for (const auto& pr : pairs) {
        for (int k = 0; k < 3; ++k) a[k] = pr[0][k] - pr[1][k], b[k] = pr[2][k] - pr[3][k];
        if ((done = pack(a, b, o))) break;
      }
      if (!done) o = {128, 128, 255, 255};  // (0, 0, 1), as packNormal packs it
    }
  }
}

void heightFieldNormals(const float* heights, size_t stride, const LevelWindow& window, const HeightFieldFrame& f,
                        PackedNormal* out) {
  const uint32_t level = window.level, u0 = window.u0, v0 = window.v0, w = window.w, h = window.h;
  // note: single precision, one reciprocal per row and column, and a truncating quantizer: this
  // runs on the loader thread for every page of a compressed atlas, and the builder calls it too,
  // so what is stored (version 1) and what is derived (version 3) agree bit for bit.
  const int64_t step = int64_t{1} << level;
  // 1 / the distance spanned, per column and row: 2^(k+1) samples inside the DEM, 2^k at its edges
  // (one-sided), 0 beyond it (flat).
  auto inverseSpan = [&](int64_t g, int64_t max, double spacing) {
    const int64_t a = std::clamp<int64_t>(g - step, 0, max), b = std::clamp<int64_t>(g + step, 0, max);
    return b > a ? static_cast<float>(1.0 / (static_cast<double>(b - a) * spacing)) : 0.f;
  };
  thread_local std::vector<float> cx;
  cx.resize(w);
  // Columns round a planet: the ring holds the wrapped neighbours, so every span is whole.
  const float wrapped = static_cast<float>(1.0 / (static_cast<double>(2 * step) * f.spacing[0]));
  for (uint32_t u = 0; u < w; ++u)
    cx[u] = f.wrapX ? wrapped : inverseSpan(f.originX + (int64_t{u0 + u} << level), f.maxX, f.spacing[0]);
  auto q = [](float c) { return static_cast<uint8_t>(c * 127.5f + 128.f); };  // c in [-1, 1]

  for (uint32_t v = 0; v < h; ++v) {
    const float cy = inverseSpan(f.originY + (int64_t{v0 + v} << level), f.maxY, f.spacing[1]);
    const float* row = heights + size_t{v} * stride;
    const float* below = row - stride;
    const float* above = row + stride;
    PackedNormal* o = out + size_t{v} * w;
    for (uint32_t u = 0; u < w; ++u) {
      // The ring holds the heights at the clamped neighbours.
      const float dx = (row[u + 1] - row[ptrdiff_t(u) - 1]) * cx[u];
      const float dy = (above[u] - below[u]) * cy;
      const float length2 = dx * dx + dy * dy + 1.f;
      if (!(length2 < std::numeric_limits<float>::infinity())) {  // slopes beyond float (a corrupt file)
        o[u] = PackedNormal{128, 128, 255, 255};
        continue;
      }
      const float inv = 1.f / std::sqrt(length2);
      o[u] = PackedNormal{q(-dx * inv), q(-dy * inv), q(inv), 255};
    }
  }
}

uint32_t AtlasManifest::intervalsLog2() const {
  if (!isChartSizeValid(chartSize))
    throw std::logic_error("AtlasManifest: chartSize " + std::to_string(chartSize) + " is not 2^m+1");
  return log2Exact(chartSize - 1);
}

LevelLayout levelLayout(uint32_t chartSize, uint32_t blockIntervals, uint32_t level) {
  if (!isChartSizeValid(chartSize) || !std::has_single_bit(blockIntervals) || blockIntervals > chartSize - 1)
    throw std::logic_error("levelLayout: bad chartSize " + std::to_string(chartSize) + " / blockIntervals " +
                           std::to_string(blockIntervals));
  const uint32_t m = chartSize - 1;
  if (level > log2Exact(m))
    throw std::logic_error("levelLayout: level " + std::to_string(level) + " > log2(" + std::to_string(m) + ")");
  const uint32_t intervals = m >> level;
  LevelLayout l;
  l.samples = intervals + 1;
  l.blocksPerSide = std::max(1u, intervals / blockIntervals);
  l.blockSamples = std::min(blockIntervals, intervals) + 1;
  return l;
}

uint32_t firstSingleBlockLevel(uint32_t chartSize, uint32_t blockIntervals) {
  levelLayout(chartSize, blockIntervals, 0);  // checks both
  return log2Exact(chartSize - 1) - log2Exact(blockIntervals);
}

// ---- atomic file writing ----------------------------------------------------------------------

AtomicFileWriter::AtomicFileWriter(fs::path path)
    : path_(std::move(path)), tmp_(path_.string() + ".tmp-" + std::to_string(::getpid())) {
  fd_ = ::open(tmp_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0)
    throw InputError(quoted(path_) + ": cannot create " + tmp_.filename().string() + ": " + std::strerror(errno));
}

AtomicFileWriter::~AtomicFileWriter() {
  if (fd_ >= 0) {
    ::close(fd_);
    ::unlink(tmp_.c_str());
  }
}

namespace {

// This process's staging directories not yet committed or removed (absolute, each with a trailing
// separator). A file written inside one is not flushed on its own: the directory's commit flushes
// its whole file system once (syncfs) before the rename that publishes it, which an output of
// many files (a mesh atlas of 80,000 charts) would otherwise wait for file by file.
std::mutex stagedMutex;
std::vector<std::string> stagedDirectories;

std::string directoryPrefix(const fs::path& dir) {
  std::string d = dir.lexically_normal().string();
  if (d.empty() || d.back() != '/') d += '/';
  return d;
}

bool insideStagedDirectory(const fs::path& file) {
  std::error_code ec;
  const std::string p = fs::absolute(file, ec).lexically_normal().string();
  if (ec) return false;
  const std::lock_guard<std::mutex> lock(stagedMutex);
  return std::any_of(stagedDirectories.begin(), stagedDirectories.end(),
                     [&](const std::string& d) { return p.compare(0, d.size(), d) == 0; });
}

void forgetStagedDirectory(const fs::path& dir) {
  const std::string d = directoryPrefix(dir);
  const std::lock_guard<std::mutex> lock(stagedMutex);
  const auto it = std::find(stagedDirectories.begin(), stagedDirectories.end(), d);
  if (it != stagedDirectories.end()) stagedDirectories.erase(it);
}

}  // namespace

void AtomicFileWriter::fail(const std::string& what, int err) {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  ::unlink(tmp_.c_str());
  throw InputError(quoted(path_) + ": " + what + ": " + std::strerror(err));
}

void AtomicFileWriter::write(const void* data, size_t bytes) {
  if (fd_ < 0) throw std::logic_error("AtomicFileWriter: write after commit or failure");
  const auto* p = static_cast<const uint8_t*>(data);
  while (bytes > 0) {
    const ssize_t w = ::write(fd_, p, std::min<size_t>(bytes, size_t{1} << 30));
    if (w < 0) {
      if (errno == EINTR) continue;
      fail("write failed", errno);
    }
    p += w;
    bytes -= static_cast<size_t>(w);
  }
}

void AtomicFileWriter::writeAt(uint64_t offset, const void* data, size_t bytes) {
  if (fd_ < 0) throw std::logic_error("AtomicFileWriter: write after commit or failure");
  const auto* p = static_cast<const uint8_t*>(data);
  while (bytes > 0) {
    const ssize_t w = ::pwrite(fd_, p, std::min<size_t>(bytes, size_t{1} << 30), off_t(offset));
    if (w < 0) {
      if (errno == EINTR) continue;
      fail("write failed", errno);
    }
    p += w;
    offset += uint64_t(w);
    bytes -= static_cast<size_t>(w);
  }
}

void AtomicFileWriter::commit() {
  if (fd_ < 0) throw std::logic_error("AtomicFileWriter: commit after commit or failure");
  if (!insideStagedDirectory(path_) && ::fdatasync(fd_) != 0 && errno != EINVAL && errno != EROFS)
    fail("flush failed", errno);
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp_.c_str());
    throw InputError(quoted(path_) + ": close failed: " + std::strerror(err));
  }
  if (::rename(tmp_.c_str(), path_.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp_.c_str());
    throw InputError(quoted(path_) + ": rename failed: " + std::strerror(err));
  }
}

std::vector<uint8_t> readFileBytes(const std::filesystem::path& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path.string() + ": cannot open (" + std::strerror(errno) + ")");
  std::vector<uint8_t> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (f.bad()) throw InputError(path.string() + ": cannot read it");
  return b;
}

void atomicWriteFile(const fs::path& path, const void* data, size_t bytes) {
  AtomicFileWriter w(path);
  w.write(data, bytes);
  w.commit();
}

// ---- manifest ---------------------------------------------------------------------------------

// The chart list file's zstd level: 16 MB of JSON codes in 0.3 s, 20% smaller than at level 3.
constexpr int kChartListLevel = 9;

void writeManifest(const fs::path& dir, const AtlasManifest& m) {
  using ojson = nlohmann::ordered_json;  // keeps "format" and "version" first
  ojson charts = ojson::array();
  for (const ChartInfo& c : m.charts) {
    ojson nb = ojson::array();
    for (const RootNeighbour& n : c.neighbours) nb.push_back(toJson(n));
    ojson chart{{"id", c.id}, {"gridX", c.gridX}, {"gridY", c.gridY}, {"file", c.file}};
    if (!c.imageryFile.empty()) chart["imagery"] = c.imageryFile;
    if (c.finestLevel != 0) chart["finest_level"] = c.finestLevel;
    chart["neighbours"] = nb;
    charts.push_back(std::move(chart));
  }
  ojson j = {
      {"format", kFormatTag},
      {"version", m.compression.present ? 2u : 1u},
      {"kind", atlasKindName(m.kind)},
      {"chartSize", m.chartSize},
      {"blockIntervals", m.blockIntervals},
      {"chartsX", m.chartsX},
      {"chartsY", m.chartsY},
      {"samplesX", m.samplesX},
      {"samplesY", m.samplesY},
      {"spacing", m.spacing},
      {"zScale", m.zScale},
      {"heightRange", {m.heightRange[0], m.heightRange[1]}},
      {"voidsFilled", m.voidsFilled},
      {"voidFillMethod", m.voidFillMethod},
      {"source", m.source},
      {"georef",
       {{"wkt", m.georef.wkt},
        {"geotransform", m.georef.geotransform},
        {"geographic", m.georef.geographic},
        {"centreLatitudeDeg", m.georef.centreLatitudeDeg}}},
  };
  if (m.planet.present)
    j["planet"] =
        ojson{{"radius", m.planet.radius},   {"lon0Deg", m.planet.lon0Deg}, {"lat0Deg", m.planet.lat0Deg},
              {"dlonDeg", m.planet.dlonDeg}, {"dlatDeg", m.planet.dlatDeg}, {"wrapColumns", m.planet.wrapColumns}};
  if (m.planet.present && m.planet.flattening > 0.0) j["planet"]["flattening"] = m.planet.flattening;
  if (m.imagery.present)
    j["imagery"] =
        ojson{{"source", m.imagery.source}, {"scaleLog2", m.imagery.scaleLog2}, {"coverage", m.imagery.coverage}};
  if (m.compression.present)
    j["compression"] = ojson{{"codec", "lorenzo-zstd"},
                             {"heightPrecision", m.compression.heightPrecision},
                             {"positionStep", m.compression.positionStep},
                             {"positionTolerance", m.compression.positionTolerance},
                             {"normalTolerance", m.compression.normalTolerance}};
  j["hierarchy"] = ojson{{"file", m.hierarchyFile},
                         {"depth", m.depth},
                         {"maxNodeResLog2", m.maxNodeResLog2},
                         {"minNodeResLog2", m.minNodeResLog2}};
  // One line per chart (a mesh atlas lists thousands; indented, each took 500 bytes).
  const bool external = m.compression.present && charts.size() > kInlineChartsMax;
  const char* const indent = external ? "\n" : "\n    ";
  std::string list = "[";
  for (size_t i = 0; i < charts.size(); ++i)
    list += (i ? "," : "") + std::string(indent) + charts[i].dump(-1, ' ', false, ojson::error_handler_t::replace);
  list += charts.empty() ? "]" : external ? "\n]\n" : "\n  ]";
  if (external) {
    const std::vector<uint8_t> coded =
        compressFrame({reinterpret_cast<const uint8_t*>(list.data()), list.size()}, kChartListLevel);
    atomicWriteFile(dir / kChartListName, coded.data(), coded.size());
    j["version"] = 3u;
    j["chartList"] = kChartListName;
  } else {
    j["charts"] = ojson::array();
  }
  // note: dump() throws on invalid UTF-8 (e.g. a Latin-1 file name in `source`); replace instead.
  std::string text = j.dump(2, ' ', false, ojson::error_handler_t::replace) + "\n";
  if (!external) {
    const std::string empty = "\"charts\": []";
    const size_t at = text.rfind(empty);
    text.replace(at, empty.size(), "\"charts\": " + list);
  }
  atomicWriteFile(dir / kManifestName, text.data(), text.size());
  std::error_code ec;
  if (!external) fs::remove(dir / kChartListName, ec);
}

namespace {

// The manifest file's JSON object, with its format tag checked.
json parseManifestFile(const fs::path& dir, const JsonReader& r) {
  const fs::path& file = r.file;
  std::error_code ec;
  if (!fs::exists(file, ec)) {
    if (!fs::exists(dir, ec)) r.fail("no such atlas directory");
    r.fail("no such file (not an atlas directory?)");
  }
  std::ifstream in(file, std::ios::binary);
  if (!in) r.fail(std::string("cannot open: ") + std::strerror(errno));
  json j;
  try {
    j = json::parse(in);
  } catch (const json::exception& e) {
    r.fail(std::string("invalid JSON: ") + e.what());
  }
  if (!j.is_object()) r.fail("invalid manifest: top level is not a JSON object");
  auto fmt = j.find("format");
  if (fmt == j.end() || !fmt->is_string() || fmt->get<std::string>() != kFormatTag)
    r.fail(std::string("not a gimlod atlas manifest (\"format\" must be \"") + kFormatTag + "\")");
  return j;
}

// The version, kind, lattice and georeference fields.
void readManifestGrid(const JsonReader& r, const json& j, AtlasManifest& m) {
  m.version = r.u32(j, "version");
  if (m.version < 1 || m.version > kAtlasFormatVersion)
    r.fail("unsupported atlas format version " + std::to_string(m.version) + " (this build reads version " +
           std::to_string(kAtlasFormatVersion) + "; rebuild the atlas)");
  const std::string kind = r.string(r.field(j, "kind", ""), "kind");
  if (kind == atlasKindName(AtlasKind::Heightfield))
    m.kind = AtlasKind::Heightfield;
  else if (kind == atlasKindName(AtlasKind::Geometry))
    m.kind = AtlasKind::Geometry;
  else
    r.fail("unknown atlas kind '" + kind + "' (expected heightfield or geometry)");
  m.chartSize = r.u32(j, "chartSize");
  if (!isChartSizeValid(m.chartSize)) r.fail("chartSize " + std::to_string(m.chartSize) + " is not 2^m+1 (3..65537)");
  m.blockIntervals = r.u32(j, "blockIntervals");
  if (!std::has_single_bit(m.blockIntervals) || m.blockIntervals > m.chartSize - 1)
    r.fail("blockIntervals " + std::to_string(m.blockIntervals) + " is not a power of two <= chartSize-1 (" +
           std::to_string(m.chartSize - 1) + ")");
  m.chartsX = r.u32(j, "chartsX");
  m.chartsY = r.u32(j, "chartsY");
  if (j.contains("samplesX")) m.samplesX = r.u32(j, "samplesX");
  if (j.contains("samplesY")) m.samplesY = r.u32(j, "samplesY");
  auto sp = r.numbers<2>(r.field(j, "spacing", ""), "spacing");
  if (sp[0] <= 0 || sp[1] <= 0) r.fail("spacing must be positive");
  m.spacing = sp;
  if (j.contains("zScale")) {
    m.zScale = r.number(j["zScale"], "zScale");
    if (m.zScale == 0) r.fail("zScale must be non-zero");
  }
  if (j.contains("heightRange")) {
    auto hr = r.numbers<2>(j["heightRange"], "heightRange");
    if (hr[0] > hr[1]) r.fail("heightRange minimum exceeds maximum");
    m.heightRange = {static_cast<float>(hr[0]), static_cast<float>(hr[1])};
  }
  if (j.contains("voidsFilled")) m.voidsFilled = r.u64(j["voidsFilled"], "voidsFilled");
  if (j.contains("voidFillMethod")) m.voidFillMethod = r.string(j["voidFillMethod"], "voidFillMethod");
  if (j.contains("source")) m.source = r.string(j["source"], "source");
  if (j.contains("georef")) {
    const json& g = j["georef"];
    if (!g.is_object()) r.fail("field 'georef' must be an object");
    if (g.contains("wkt")) m.georef.wkt = r.string(g["wkt"], "georef.wkt");
    if (g.contains("geotransform")) m.georef.geotransform = r.numbers<6>(g["geotransform"], "georef.geotransform");
    if (g.contains("geographic")) m.georef.geographic = r.boolean(g["geographic"], "georef.geographic");
    if (g.contains("centreLatitudeDeg"))
      m.georef.centreLatitudeDeg = r.number(g["centreLatitudeDeg"], "georef.centreLatitudeDeg");
  }
}

// The planet a heightfield atlas is drawn on (core/planet.h), where there is one.
void readManifestPlanet(const JsonReader& r, const json& j, AtlasManifest& m) {
  if (j.contains("planet") && !j["planet"].is_null()) {
    const json& pl = j["planet"];
    if (!pl.is_object()) r.fail("field 'planet' must be an object or null");
    if (m.kind != AtlasKind::Heightfield) r.fail("field 'planet' is for heightfield atlases only");
    PlanetInfo& p = m.planet;
    p.present = true;
    p.radius = r.number(r.field(pl, "radius", "planet."), "planet.radius");
    p.lon0Deg = r.number(r.field(pl, "lon0Deg", "planet."), "planet.lon0Deg");
    p.lat0Deg = r.number(r.field(pl, "lat0Deg", "planet."), "planet.lat0Deg");
    p.dlonDeg = r.number(r.field(pl, "dlonDeg", "planet."), "planet.dlonDeg");
    p.dlatDeg = r.number(r.field(pl, "dlatDeg", "planet."), "planet.dlatDeg");
    p.wrapColumns = uint32_t(r.integer(r.field(pl, "wrapColumns", "planet."), "planet.wrapColumns", 0, INT32_MAX));
    if (pl.contains("flattening")) p.flattening = r.number(pl["flattening"], "planet.flattening");
    if (!(p.radius >= 1.0 && p.radius <= 1e9)) r.fail("planet.radius must be between 1 m and 1e9 m");
    if (!(p.flattening >= 0.0 && p.flattening <= kMaxPlanetFlattening))
      r.fail("planet.flattening must be between 0 (a sphere) and " + std::to_string(kMaxPlanetFlattening));
    if (!(p.dlonDeg > 0.0 && p.dlonDeg <= 360.0 && p.dlatDeg > 0.0 && p.dlatDeg <= 180.0))
      r.fail("planet.dlonDeg and planet.dlatDeg must be positive (at most 360 and 180 degrees)");
    if (!(std::fabs(p.lon0Deg) <= 720.0 && std::fabs(p.lat0Deg) <= 180.0))
      r.fail("planet.lon0Deg or planet.lat0Deg is out of range");
  }
}

// The imagery and compression records.
void readManifestImageryAndCompression(const JsonReader& r, const json& j, AtlasManifest& m) {
  if (j.contains("imagery") && !j["imagery"].is_null()) {
    const json& im = j["imagery"];
    if (!im.is_object()) r.fail("field 'imagery' must be an object or null");
    if (m.kind != AtlasKind::Heightfield) r.fail("field 'imagery' is for heightfield atlases only");
    m.imagery.present = true;
    m.imagery.scaleLog2 =
        uint32_t(r.integer(r.field(im, "scaleLog2", "imagery."), "imagery.scaleLog2", 0, kMaxImageryScaleLog2));
    if (im.contains("source")) m.imagery.source = r.string(im["source"], "imagery.source");
    if (im.contains("coverage")) m.imagery.coverage = r.number(im["coverage"], "imagery.coverage");
  }
  if (j.contains("compression") && !j["compression"].is_null()) {
    const json& c = j["compression"];
    if (!c.is_object()) r.fail("field 'compression' must be an object or null");
    const std::string codec = r.string(r.field(c, "codec", "compression."), "compression.codec");
    if (codec != "lorenzo-zstd") r.fail("unknown compression codec '" + codec + "' (expected lorenzo-zstd)");
    m.compression.present = true;
    if (c.contains("heightPrecision"))
      m.compression.heightPrecision = r.number(c["heightPrecision"], "compression.heightPrecision");
    if (c.contains("positionStep"))
      m.compression.positionStep = r.number(c["positionStep"], "compression.positionStep");
    if (c.contains("positionTolerance"))
      m.compression.positionTolerance = r.number(c["positionTolerance"], "compression.positionTolerance");
    if (c.contains("normalTolerance")) {
      const double t = r.number(c["normalTolerance"], "compression.normalTolerance");
      if (!(t >= 0.0 && t <= 127.0) || t != std::floor(t))
        r.fail("compression.normalTolerance must be a whole number in [0, 127]");
      m.compression.normalTolerance = uint32_t(t);
    }
    if (!(m.compression.heightPrecision >= 0.0) || !(m.compression.positionStep >= 0.0) ||
        !(m.compression.positionTolerance >= 0.0))
      r.fail("compression steps and tolerances must be >= 0");
  }
  if ((m.version >= 2) != m.compression.present)
    r.fail(m.compression.present ? "field 'compression' needs format version 2"
                                 : "format version 2 needs the field 'compression'");
}

// The hierarchy record, checked against the lattice.
void readManifestHierarchy(const JsonReader& r, const json& j, AtlasManifest& m) {
  const uint32_t ilog = log2Exact(m.chartSize - 1);
  if (j.contains("hierarchy")) {
    const json& h = j["hierarchy"];
    if (!h.is_object()) r.fail("field 'hierarchy' must be an object");
    if (h.contains("file")) m.hierarchyFile = r.string(h["file"], "hierarchy.file");
    if (h.contains("depth")) m.depth = r.u32(h, "depth", "hierarchy.");
    if (h.contains("maxNodeResLog2")) m.maxNodeResLog2 = r.u32(h, "maxNodeResLog2", "hierarchy.");
    if (h.contains("minNodeResLog2")) m.minNodeResLog2 = r.u32(h, "minNodeResLog2", "hierarchy.");
  }
  if (m.depth < 1 || m.depth > ilog + 1)
    r.fail("hierarchy.depth " + std::to_string(m.depth) + " must be in [1, " + std::to_string(ilog + 1) + "]");
  if (m.minNodeResLog2 > m.maxNodeResLog2 || m.maxNodeResLog2 > log2Exact(m.blockIntervals))
    r.fail("hierarchy node resolutions must satisfy minNodeResLog2 (" + std::to_string(m.minNodeResLog2) +
           ") <= maxNodeResLog2 (" + std::to_string(m.maxNodeResLog2) + ") <= log2(blockIntervals) (" +
           std::to_string(log2Exact(m.blockIntervals)) + ")");
}

// charts[i] of n: its file, grid position and neighbours.
void readManifestChart(const JsonReader& r, const json& c, size_t i, int64_t n, AtlasManifest& m) {
  const bool grid = m.kind == AtlasKind::Heightfield;
  const std::string ctx = "charts[" + std::to_string(i) + "].";
  if (!c.is_object()) r.fail("field 'charts[" + std::to_string(i) + "]' must be an object");
  ChartInfo& ci = m.charts[i];
  ci.id = r.u32(c, "id", ctx);
  if (ci.id != i)
    r.fail("inconsistent chart list: " + ctx + "id is " + std::to_string(ci.id) + ", expected " + std::to_string(i));
  ci.gridX = static_cast<int32_t>(r.integer(r.field(c, "gridX", ctx), ctx + "gridX", 0, INT32_MAX));
  ci.gridY = static_cast<int32_t>(r.integer(r.field(c, "gridY", ctx), ctx + "gridY", 0, INT32_MAX));
  if (grid && (static_cast<uint32_t>(ci.gridX) >= m.chartsX || static_cast<uint32_t>(ci.gridY) >= m.chartsY ||
               static_cast<uint32_t>(ci.gridY) * m.chartsX + static_cast<uint32_t>(ci.gridX) != i))
    r.fail("inconsistent chart list: " + ctx + "grid position (" + std::to_string(ci.gridX) + ", " +
           std::to_string(ci.gridY) + ") does not match its id in a " + std::to_string(m.chartsX) + " x " +
           std::to_string(m.chartsY) + " grid");
  ci.file = r.string(r.field(c, "file", ctx), ctx + "file");
  const auto insideAtlas = [&](const std::string& file, const std::string& key) {
    const fs::path fp(file);
    if (file.empty() || fp.is_absolute() ||
        std::any_of(fp.begin(), fp.end(), [](const fs::path& e) { return e == ".."; }))
      r.fail("field '" + ctx + key + "' must be a relative path inside the atlas: '" + file + "'");
  };
  insideAtlas(ci.file, "file");
  if (m.imagery.present) {
    ci.imageryFile = r.string(r.field(c, "imagery", ctx), ctx + "imagery");
    insideAtlas(ci.imageryFile, "imagery");
  }
  if (c.contains("finest_level")) {
    if (m.kind != AtlasKind::Geometry) r.fail("field '" + ctx + "finest_level' is for geometry atlases only");
    ci.finestLevel =
        static_cast<uint32_t>(r.integer(c["finest_level"], ctx + "finest_level", 0, int64_t(m.intervalsLog2())));
  }
  const json& nb = r.field(c, "neighbours", ctx);
  if (!nb.is_array() || nb.size() != 4) r.fail("field '" + ctx + "neighbours' must have 4 entries");
  for (size_t e = 0; e < 4; ++e) {
    const std::string nctx = ctx + "neighbours[" + std::to_string(e) + "].";
    RootNeighbour& rn = ci.neighbours[e];
    rn.chart = static_cast<int32_t>(r.integer(r.field(nb[e], "chart", nctx), nctx + "chart", -1, n - 1));
    rn.edge = static_cast<uint8_t>(r.integer(r.field(nb[e], "edge", nctx), nctx + "edge", 0, 3));
    if (nb[e].contains("reversed")) rn.reversed = r.boolean(nb[e]["reversed"], nctx + "reversed");
  }
}

// The chart list of a version 3 manifest: its file's JSON array. Errors name that file.
json readChartList(const fs::path& dir, const JsonReader& r, const json& j) {
  if (j.contains("charts")) r.fail("a version 3 manifest has 'chartList' in place of 'charts', not both");
  const std::string name = r.string(r.field(j, "chartList", ""), "chartList");
  const fs::path rel(name);
  if (name.empty() || rel.is_absolute() ||
      std::any_of(rel.begin(), rel.end(), [](const fs::path& e) { return e == ".."; }))
    r.fail("field 'chartList' must be a relative path inside the atlas: '" + name + "'");
  const fs::path file = dir / rel;
  const JsonReader lr{file};
  const std::vector<uint8_t> coded = readFileBytes(file);
  std::vector<uint8_t> text;
  try {
    // A JSON chart list codes at least 4 times smaller; a frame claiming far more is corrupt.
    text = decompressFrame(coded, 4096 * coded.size() + (size_t(1) << 20));
  } catch (const CodecError& e) {
    lr.fail(std::string("not a chart list (one zstd frame of JSON): ") + e.what());
  }
  json list;
  try {
    list = json::parse(text.begin(), text.end());
  } catch (const json::exception& e) {
    lr.fail(std::string("invalid JSON: ") + e.what());
  }
  return list;
}

// The chart list; neighbour relations must be symmetric.
void readManifestCharts(const JsonReader& r, const json& cs, AtlasManifest& m) {
  if (!cs.is_array()) r.fail("field 'charts' must be an array");
  if (cs.empty()) r.fail("inconsistent chart list: no charts");
  if (cs.size() > (size_t{1} << 24)) r.fail("inconsistent chart list: too many charts");
  const bool grid = m.kind == AtlasKind::Heightfield;
  if (grid && static_cast<uint64_t>(m.chartsX) * m.chartsY != cs.size())
    r.fail("inconsistent chart list: " + std::to_string(cs.size()) +
           " charts but chartsX * chartsY = " + std::to_string(m.chartsX) + " * " + std::to_string(m.chartsY));
  const int64_t n = static_cast<int64_t>(cs.size());
  m.charts.resize(cs.size());
  for (size_t i = 0; i < cs.size(); ++i) readManifestChart(r, cs[i], i, n, m);
  // Neighbour relations must be symmetric.
  for (size_t i = 0; i < m.charts.size(); ++i) {
    for (uint8_t e = 0; e < 4; ++e) {
      const RootNeighbour& a = m.charts[i].neighbours[e];
      if (a.chart < 0) continue;
      const RootNeighbour& b = m.charts[static_cast<size_t>(a.chart)].neighbours[a.edge];
      if (b.chart != static_cast<int32_t>(i) || b.edge != e || b.reversed != a.reversed)
        r.fail("inconsistent chart list: chart " + std::to_string(i) + " edge " + std::to_string(e) + " names chart " +
               std::to_string(a.chart) + " edge " + std::to_string(a.edge) + ", which does not name it back");
    }
  }
}

}  // namespace

AtlasManifest readManifest(const fs::path& dir) {
  const fs::path file = dir / kManifestName;
  const JsonReader r{file};
  const json j = parseManifestFile(dir, r);
  AtlasManifest m;
  readManifestGrid(r, j, m);
  readManifestPlanet(r, j, m);
  readManifestImageryAndCompression(r, j, m);
  readManifestHierarchy(r, j, m);
  if (m.version >= 3) {
    const json list = readChartList(dir, r, j);
    readManifestCharts(JsonReader{dir / j["chartList"].get<std::string>()}, list, m);
  } else {
    readManifestCharts(r, r.field(j, "charts", ""), m);
  }
  return m;
}

// ---- chart files ------------------------------------------------------------------------------

struct ChartFileWriter::Impl {
  uint32_t chartSize = 0, blockIntervals = 0, levels = 0;
  uint32_t storedLevels = 0;  // levels with blocks (all but those flag 8 leaves out)
  uint32_t mask = 0;          // channels of the chart
  uint32_t stored = 0;        // channels stored (a derived height field stores no normals)
  ChartCoding coding;
  bool v1 = false, derived = false, borderNormals = false;
  size_t entryBytes = 0;
  std::vector<LevelLayout> layouts;
  std::vector<size_t> levelEntry;  // directory entry of each level's first block
  std::vector<uint8_t> directory;  // entries, filled as blocks come
  std::vector<uint8_t> written;    // per block
  size_t header = 0;
  std::mutex mutex;
  AtomicFileWriter file;
  uint64_t end = 0;  // bytes so far

  explicit Impl(const fs::path& path) : file(path) {}

  // Channel c of `block` (its level and place) from `in`, gathered row by row (into `raw`, scratch)
  // and coded (version 3) or made little-endian into block.bytes[c].
  void blockBytes(uint32_t c, const BlockChannel& in, std::vector<uint8_t>& raw, CodedBlock& block) const {
    const LevelLayout& l = layouts[block.level];
    const uint32_t bx = block.bx, by = block.by;
    std::vector<uint8_t>& out = block.bytes[c];
    const size_t es = kChannelBytes[c];
    const uint32_t bs = l.blockSamples;
    const bool ring = derived && c == kChannelHeights;  // (bs + 2)^2 from the ring heights
    const uint32_t side = ring ? bs + 2 : bs;
    if (!in.data || in.stride < side) throw std::invalid_argument("ChartFileWriter: a block lacks a channel's samples");
    raw.resize(size_t{side} * side * es);
    for (uint32_t v = 0; v < side; ++v)
      std::memcpy(raw.data() + size_t{v} * side * es, static_cast<const uint8_t*>(in.data) + size_t{v} * in.stride * es,
                  size_t{side} * es);
    const size_t count = size_t{bs} * bs;
    if (!coding.compressed) {
      if (kChannelIsFloat[c])
        for (size_t i = 0; i < raw.size() / sizeof(float); ++i) {
          float f;
          std::memcpy(&f, raw.data() + i * sizeof(float), sizeof(float));
          f = toLittle(f);
          std::memcpy(raw.data() + i * sizeof(float), &f, sizeof(float));
        }
      out.swap(raw);
      return;
    }
    switch (c) {
      case kChannelHeights:
        out = encodeHeights({reinterpret_cast<const float*>(raw.data()), size_t{side} * side}, side,
                            coding.heightPrecision);
        break;
      case kChannelPositions:
        out = encodePositions({reinterpret_cast<const float*>(raw.data()), 3 * count}, bs, coding.positionStep,
                              (by == 0 ? kChartBorderBottom : 0) | (bx == 0 ? kChartBorderLeft : 0) |
                                  (by + 1 == l.blocksPerSide ? kChartBorderTop : 0) |
                                  (bx + 1 == l.blocksPerSide ? kChartBorderRight : 0));
        break;
      case kChannelNormals:
        out = borderNormals ? encodeBorderNormals({reinterpret_cast<const PackedNormal*>(raw.data()), count}, bs)
                            : encodeNormals({reinterpret_cast<const PackedNormal*>(raw.data()), count}, bs);
        break;
      default: out = encodeColours({reinterpret_cast<const PackedColour*>(raw.data()), count}, bs); break;
    }
  }
};

ChartFileWriter::ChartFileWriter(fs::path path, const ChartFileShape& shape, const ChartCoding& coding,
                                 std::optional<HeightFieldFrame> frame)
    : path_(std::move(path)) {
  const uint32_t chartSize = shape.chartSize, blockIntervals = shape.blockIntervals, levels = shape.levels;
  const uint32_t channelMask = shape.channelMask;
  if (!isChartSizeValid(chartSize) || !std::has_single_bit(blockIntervals) || blockIntervals > chartSize - 1)
    throw std::invalid_argument("ChartFileWriter: bad chartSize/blockIntervals");
  const uint32_t mask = channelMask;
  const bool heightField = mask == kHeightFieldMask;
  const bool geometry =
      (mask & (1u << kChannelPositions)) && (mask & (1u << kChannelNormals)) && !(mask & (1u << kChannelHeights));
  if (!heightField && !geometry && mask != kAttributeMask)
    throw std::invalid_argument(
        "ChartFileWriter: a chart has heights and normals, or positions and normals (and colours), or colours alone");
  if (levels < 1 || levels > log2Exact(chartSize - 1) + 1)
    throw std::invalid_argument("ChartFileWriter: bad pyramid level count");
  if (coding.compressed && (mask & (1u << kChannelPositions)) && !(coding.positionStep > 0.0))
    throw std::invalid_argument("ChartFileWriter: compressed positions need a positionStep > 0");
  if (frame && !(coding.compressed && heightField))
    throw std::invalid_argument("ChartFileWriter: only a compressed height field derives its normals");
  if (shape.subsampledLevels && !(coding.compressed && geometry))
    throw std::invalid_argument("ChartFileWriter: only a compressed geometry chart leaves its coarse levels out");
  impl_ = std::make_unique<Impl>(path_);
  Impl& w = *impl_;
  w.chartSize = chartSize;
  w.blockIntervals = blockIntervals;
  w.levels = levels;
  w.storedLevels =
      shape.subsampledLevels ? std::min(levels, firstSingleBlockLevel(chartSize, blockIntervals) + 1) : levels;
  w.mask = mask;
  w.coding = coding;
  w.v1 = heightField && !coding.compressed;
  w.derived = frame.has_value();
  w.stored = w.derived ? mask & ~(1u << kChannelNormals) : mask;
  w.borderNormals = coding.compressed && geometry && coding.deriveGeometryNormals;
  w.header = coding.compressed ? kChartHeaderBytesV3 + (w.derived ? kFrameBytes : 0)
             : w.v1            ? kChartHeaderBytes
                               : kChartHeaderBytesV2;
  w.entryBytes = coding.compressed ? kCodedEntryBytes * size_t(std::popcount(w.stored))
                 : w.v1            ? kDirEntryBytes
                                   : 8 * size_t(std::popcount(mask));
  size_t entries = 0;
  for (uint32_t k = 0; k < w.storedLevels; ++k) {
    w.layouts.push_back(levelLayout(chartSize, blockIntervals, k));
    w.levelEntry.push_back(entries);
    entries += size_t{w.layouts[k].blocksPerSide} * w.layouts[k].blocksPerSide;
  }
  w.written.assign(entries, 0);
  // The header, then the directory as it will be.
  w.directory.assign(w.header + entries * w.entryBytes, 0);
  std::vector<uint8_t>& buf = w.directory;
  std::memcpy(buf.data(), kChartMagic, 4);
  putLe<uint32_t>(buf, 4,
                  coding.compressed ? kChartFileVersionCoded
                  : w.v1            ? kChartFileVersion
                                    : kChartFileVersionChannels);
  putLe<uint32_t>(buf, 8, chartSize);
  putLe<uint32_t>(buf, 12, blockIntervals);
  putLe<uint32_t>(buf, 16, levels);
  if (!w.v1) putLe<uint32_t>(buf, 20, mask);
  if (coding.compressed) {
    putLe<uint32_t>(buf, 24,
                    (w.derived         ? kFlagDerivedNormals | (frame->wrapX ? kFlagWrapColumns : 0)
                     : w.borderNormals ? kFlagBorderNormals
                                       : 0) |
                        (shape.subsampledLevels ? kFlagSubsampledLevels : 0));
    if (w.derived) {
      putLe<int64_t>(buf, 28, frame->originX);
      putLe<int64_t>(buf, 36, frame->originY);
      putLe<int64_t>(buf, 44, frame->maxX);
      putLe<int64_t>(buf, 52, frame->maxY);
      putLe<double>(buf, 60, frame->spacing[0]);
      putLe<double>(buf, 68, frame->spacing[1]);
    }
  }
  w.file.write(buf.data(), buf.size());
  w.end = buf.size();
}

ChartFileWriter::~ChartFileWriter() = default;
uint32_t ChartFileWriter::chartSize() const { return impl_->chartSize; }
uint32_t ChartFileWriter::blockIntervals() const { return impl_->blockIntervals; }

ChartFileWriter::CodedBlock ChartFileWriter::code(uint32_t level, uint32_t bx, uint32_t by,
                                                  const BlockData& data) const {
  const Impl& w = *impl_;
  if (level >= w.storedLevels || bx >= w.layouts[level].blocksPerSide || by >= w.layouts[level].blocksPerSide)
    throw std::logic_error("ChartFileWriter: no block (" + std::to_string(bx) + ", " + std::to_string(by) +
                           ") on level " + std::to_string(level));
  CodedBlock out{level, bx, by, {}};
  std::vector<uint8_t> raw;
  for (uint32_t c = 0; c < kChannelCount; ++c)
    if (w.stored & (1u << c)) w.blockBytes(c, data[c], raw, out);
  return out;
}

void ChartFileWriter::append(const CodedBlock& block) {
  Impl& w = *impl_;
  const LevelLayout& l = w.layouts.at(block.level);
  const size_t entry = w.levelEntry[block.level] + size_t{block.by} * l.blocksPerSide + block.bx;
  const std::lock_guard<std::mutex> lock(w.mutex);
  if (w.written.at(entry)) throw std::logic_error("ChartFileWriter: block written twice");
  w.written[entry] = 1;
  size_t at = w.header + entry * w.entryBytes;
  for (uint32_t c = 0; c < kChannelCount; ++c) {
    if (!(w.stored & (1u << c))) continue;
    putLe<uint64_t>(w.directory, at, w.end);
    at += 8;
    if (w.coding.compressed) {
      putLe<uint32_t>(w.directory, at, uint32_t(block.bytes[c].size()));
      at += 4;
    }
    w.file.write(block.bytes[c].data(), block.bytes[c].size());
    w.end += block.bytes[c].size();
  }
}

uint64_t ChartFileWriter::commit() {
  Impl& w = *impl_;
  const std::lock_guard<std::mutex> lock(w.mutex);
  if (std::find(w.written.begin(), w.written.end(), 0) != w.written.end())
    throw std::logic_error("ChartFileWriter: " + path_.string() + ": a block was not written");
  w.file.writeAt(0, w.directory.data(), w.directory.size());
  w.file.commit();
  return w.end;
}

uint64_t ChartFileWriter::commitPartial() {
  Impl& w = *impl_;
  const std::lock_guard<std::mutex> lock(w.mutex);
  w.file.writeAt(0, w.directory.data(), w.directory.size());
  w.file.commit();
  return w.end;
}

ChartFileWriter::ChartFileWriter(fs::path path, const ChartFileShape& shape, const ChartCoding& coding,
                                 const fs::path& partial)
    : ChartFileWriter(std::move(path), shape, coding) {
  Impl& w = *impl_;
  std::ifstream in(partial, std::ios::binary);
  std::error_code ec;
  const uint64_t size = fs::file_size(partial, ec);
  const size_t head = w.directory.size();
  std::vector<uint8_t> directory(head);
  if (!in || ec || size < head || !in.read(reinterpret_cast<char*>(directory.data()), std::streamsize(head)) ||
      !std::equal(w.directory.begin(), w.directory.begin() + std::ptrdiff_t(w.header), directory.begin()))
    throw InputError(quoted(partial) + ": not a partial chart file of this shape and coding");
  // A block's entry holds its first stored channel's offset, past the directory once written.
  for (size_t e = 0; e < w.written.size(); ++e) {
    const size_t at = w.header + e * w.entryBytes;
    const uint64_t offset = getLe<uint64_t>(directory.data() + at);
    if (offset == 0) continue;
    if (offset < head || offset > size) throw InputError(quoted(partial) + ": a block's offset lies outside the file");
    w.written[e] = 1;
    std::copy_n(directory.begin() + std::ptrdiff_t(at), w.entryBytes, w.directory.begin() + std::ptrdiff_t(at));
  }
  // The blocks, a piece at a time.
  std::vector<char> piece(size_t{4} << 20);
  for (uint64_t left = size - head; left > 0;) {
    const size_t n = size_t(std::min<uint64_t>(left, piece.size()));
    if (!in.read(piece.data(), std::streamsize(n))) throw InputError(quoted(partial) + ": cannot read it");
    w.file.write(piece.data(), n);
    left -= n;
  }
  w.end = size;
}

bool coarseLevelsSubsampled(const ChartPyramid& pyramid, uint32_t chartSize, uint32_t blockIntervals) {
  if (pyramid.positions.empty() || !pyramid.heights.empty()) return false;
  const uint32_t s = firstSingleBlockLevel(chartSize, blockIntervals);
  auto subsamples = [&](const auto& levels) {
    if (levels.empty()) return true;
    if (levels.size() != pyramid.positions.size() || levels.size() <= s) return false;
    const uint32_t from = ((chartSize - 1) >> s) + 1;
    if (levels[s].size() != size_t{from} * from) return false;
    for (uint32_t k = s + 1; k < levels.size(); ++k) {
      const uint32_t side = ((chartSize - 1) >> k) + 1, step = 1u << (k - s);
      if (levels[k].size() != size_t{side} * side) return false;
      for (uint32_t v = 0; v < side; ++v)
        for (uint32_t u = 0; u < side; ++u)
          if (std::memcmp(&levels[k][size_t{v} * side + u], &levels[s][size_t{v * step} * from + u * step],
                          sizeof(levels[k][0])) != 0)
            return false;
    }
    return true;
  };
  return subsamples(pyramid.positions) && subsamples(pyramid.normals) && subsamples(pyramid.colours);
}

uint64_t writeChartFile(const fs::path& path, const ChartPyramid& pyramid, uint32_t chartSize, uint32_t blockIntervals,
                        const ChartCoding& coding) {
  if (!isChartSizeValid(chartSize) || !std::has_single_bit(blockIntervals) || blockIntervals > chartSize - 1)
    throw std::invalid_argument("writeChartFile: bad chartSize/blockIntervals");
  // Channels present, as levels of samples.
  std::array<std::vector<const uint8_t*>, kChannelCount> data;
  std::array<size_t, kChannelCount> counts{};
  std::array<std::vector<size_t>, kChannelCount> sizes;
  auto add = [&](ChartChannel c, const auto& levels) {
    counts[c] = levels.size();
    for (const auto& l : levels) {
      data[c].push_back(reinterpret_cast<const uint8_t*>(l.data()));
      sizes[c].push_back(l.size());
    }
  };
  add(kChannelHeights, pyramid.heights);
  add(kChannelNormals, pyramid.normals);
  add(kChannelPositions, pyramid.positions);
  add(kChannelColours, pyramid.colours);
  uint32_t mask = 0;
  for (uint32_t c = 0; c < kChannelCount; ++c)
    if (counts[c] != 0) mask |= 1u << c;
  // Compressed height fields with their ring heights derive their normals on reading (the pyramid
  // may then hold none).
  const bool ringed = coding.compressed && !pyramid.heights.empty() && pyramid.frame &&
                      pyramid.ringHeights.size() == pyramid.heights.size();
  if (ringed && mask == (1u << kChannelHeights)) mask = kHeightFieldMask;
  const uint32_t levels = static_cast<uint32_t>(mask == kAttributeMask     ? pyramid.colours.size()
                                                : mask == kHeightFieldMask ? pyramid.heights.size()
                                                                           : pyramid.normals.size());
  for (uint32_t c = 0; c < kChannelCount; ++c)
    if (counts[c] != 0 && counts[c] != levels)
      throw std::invalid_argument("writeChartFile: channels have different level counts");
  const bool derived = ringed && mask == kHeightFieldMask;
  if (levels < 1 || levels > log2Exact(chartSize - 1) + 1)
    throw std::invalid_argument("writeChartFile: bad pyramid level count");
  for (uint32_t k = 0; k < levels; ++k) {
    const size_t s = levelLayout(chartSize, blockIntervals, k).samples;
    for (uint32_t c = 0; c < kChannelCount; ++c)
      if (counts[c] != 0 && sizes[c][k] != s * s)
        throw std::invalid_argument("writeChartFile: level " + std::to_string(k) + " has the wrong number of samples");
    if (derived && pyramid.ringHeights[k].size() != (s + 2) * (s + 2))
      throw std::invalid_argument("writeChartFile: level " + std::to_string(k) + " ring heights are not (samples+2)^2");
  }
  std::optional<HeightFieldFrame> frame;
  if (derived) frame = pyramid.frame;
  // A compressed geometry chart whose coarse levels subsample the first one-block level stores
  // none of them.
  const bool subsampled = coding.compressed && (mask & (1u << kChannelPositions)) &&
                          levels > firstSingleBlockLevel(chartSize, blockIntervals) + 1 &&
                          coarseLevelsSubsampled(pyramid, chartSize, blockIntervals);
  ChartFileWriter writer(path, {chartSize, blockIntervals, levels, mask, subsampled}, coding, frame);
  const uint32_t stored = subsampled ? firstSingleBlockLevel(chartSize, blockIntervals) + 1 : levels;
  for (uint32_t k = 0; k < stored; ++k) {
    const LevelLayout l = levelLayout(chartSize, blockIntervals, k);
    const uint32_t b = l.blockSamples - 1;
    for (uint32_t by = 0; by < l.blocksPerSide; ++by)
      for (uint32_t bx = 0; bx < l.blocksPerSide; ++bx) {
        BlockData block;
        for (uint32_t c = 0; c < kChannelCount; ++c) {
          if (counts[c] == 0) continue;
          const size_t at = size_t{by * b} * l.samples + size_t{bx} * b;
          block[c] = {data[c][k] + at * kChannelBytes[c], l.samples};
        }
        if (derived) {
          const size_t rs = size_t{l.samples} + 2;
          block[kChannelHeights] = {pyramid.ringHeights[k].data() + size_t{by * b} * rs + size_t{bx} * b, rs};
        }
        writer.writeBlock(k, bx, by, block);
      }
  }
  return writer.commit();
}

ChartFileReader::ChartFileReader(const fs::path& path) : path_(path) {
  static std::atomic<uint64_t> readers{0};
  serial_ = ++readers;
  auto fail = [&](const std::string& what) { throw InputError(quoted(path_) + ": " + what); };
  std::error_code ec;
  const uint64_t fileSize = fs::file_size(path_, ec);
  if (ec) fail("cannot read chart file: " + ec.message());
  file_.open(path_, std::ios::binary);
  if (!file_) fail(std::string("cannot open chart file: ") + std::strerror(errno));
  uint8_t hdr[kChartHeaderBytes];
  if (fileSize < kChartHeaderBytes || !file_.read(reinterpret_cast<char*>(hdr), sizeof hdr))
    fail("truncated chart file (no header)");
  if (std::memcmp(hdr, kChartMagic, 4) != 0) fail("not a gimlod chart file (bad magic)");
  const uint32_t version = getLe<uint32_t>(hdr + 4);
  if (version != kChartFileVersion && version != kChartFileVersionChannels && version != kChartFileVersionCoded)
    fail("unsupported chart file version " + std::to_string(version));
  channelMask_ = kHeightFieldMask;
  compressed_ = version == kChartFileVersionCoded;
  size_t header = kChartHeaderBytes;
  if (version != kChartFileVersion) {
    uint8_t m[4];
    if (fileSize < kChartHeaderBytesV2 || !file_.read(reinterpret_cast<char*>(m), 4))
      fail("truncated chart file (no channel mask)");
    channelMask_ = getLe<uint32_t>(m);
    header = kChartHeaderBytesV2;
    if (channelMask_ != kAttributeMask &&
        (channelMask_ == 0 || channelMask_ >= (1u << kChannelCount) || !(channelMask_ & (1u << kChannelNormals)) ||
         ((channelMask_ >> kChannelHeights) & 1u) == ((channelMask_ >> kChannelPositions) & 1u)))
      fail("corrupt chart header (channel mask " + std::to_string(channelMask_) + ")");
  }
  uint32_t stored = channelMask_;  // channels with blocks in the file
  bool subsampledLevels = false;
  if (compressed_) {
    uint8_t fl[4];
    if (fileSize < kChartHeaderBytesV3 || !file_.read(reinterpret_cast<char*>(fl), 4))
      fail("truncated chart file (no flags)");
    const uint32_t flags = getLe<uint32_t>(fl);
    header = kChartHeaderBytesV3;
    if ((flags & ~(kFlagDerivedNormals | kFlagBorderNormals | kFlagWrapColumns | kFlagSubsampledLevels)) ||
        (flags & kFlagDerivedNormals && flags & kFlagBorderNormals) ||
        (flags & kFlagWrapColumns && !(flags & kFlagDerivedNormals)))
      fail("corrupt chart header (flags " + std::to_string(flags) + ")");
    if (flags & kFlagSubsampledLevels) {
      if (!(channelMask_ & (1u << kChannelPositions)))
        fail("corrupt chart header (subsampled levels without positions)");
      subsampledLevels = true;
    }
    if (flags & kFlagBorderNormals) {
      if (!(channelMask_ & (1u << kChannelPositions))) fail("corrupt chart header (border normals without positions)");
      borderNormals_ = true;
    }
    if (flags & kFlagDerivedNormals) {
      if (channelMask_ != kHeightFieldMask) fail("corrupt chart header (derived normals without heights)");
      uint8_t fr[kFrameBytes];
      if (fileSize < kChartHeaderBytesV3 + kFrameBytes || !file_.read(reinterpret_cast<char*>(fr), kFrameBytes))
        fail("truncated chart file (no height-field frame)");
      HeightFieldFrame f;
      f.originX = getLe<int64_t>(fr);
      f.originY = getLe<int64_t>(fr + 8);
      f.maxX = getLe<int64_t>(fr + 16);
      f.maxY = getLe<int64_t>(fr + 24);
      f.spacing = {getLe<double>(fr + 32), getLe<double>(fr + 40)};
      f.wrapX = (flags & kFlagWrapColumns) != 0;
      constexpr int64_t kLimit = int64_t{1} << 40;
      if (f.originX < 0 || f.originY < 0 || f.originX > kLimit || f.originY > kLimit || f.maxX < 0 || f.maxY < 0 ||
          f.maxX > kLimit || f.maxY > kLimit || !(f.spacing[0] > 0.0) || !(f.spacing[1] > 0.0) ||
          !std::isfinite(f.spacing[0]) || !std::isfinite(f.spacing[1]))
        fail("corrupt chart header (height-field frame)");
      frame_ = f;
      header += kFrameBytes;
      stored &= ~(1u << kChannelNormals);
    }
  }
  const size_t entryBytes = version == kChartFileVersion ? kDirEntryBytes
                            : compressed_                ? kCodedEntryBytes * size_t(std::popcount(stored))
                                                         : 8 * size_t(std::popcount(channelMask_));
  chartSize_ = getLe<uint32_t>(hdr + 8);
  blockIntervals_ = getLe<uint32_t>(hdr + 12);
  levels_ = getLe<uint32_t>(hdr + 16);
  if (!isChartSizeValid(chartSize_) || !std::has_single_bit(blockIntervals_) || blockIntervals_ > chartSize_ - 1 ||
      levels_ < 1 || levels_ > log2Exact(chartSize_ - 1) + 1)
    fail("corrupt chart header (chartSize " + std::to_string(chartSize_) + ", blockIntervals " +
         std::to_string(blockIntervals_) + ", levels " + std::to_string(levels_) + ")");
  storedLevels_ =
      subsampledLevels ? std::min(levels_, firstSingleBlockLevel(chartSize_, blockIntervals_) + 1) : levels_;
  size_t entries = 0;
  for (uint32_t k = 0; k < storedLevels_; ++k) {
    const LevelLayout l = levelLayout(chartSize_, blockIntervals_, k);
    entries += size_t{l.blocksPerSide} * l.blocksPerSide;
  }
  const uint64_t dirEnd = header + uint64_t{entries} * entryBytes;
  if (fileSize < dirEnd) fail("truncated chart file (block directory incomplete)");
  std::vector<uint8_t> dir(entries * entryBytes);
  if (!file_.read(reinterpret_cast<char*>(dir.data()), static_cast<std::streamsize>(dir.size())))
    fail("truncated chart file (block directory unreadable)");
  directory_.resize(storedLevels_);
  size_t at = 0;
  for (uint32_t k = 0; k < storedLevels_; ++k) {
    const LevelLayout l = levelLayout(chartSize_, blockIntervals_, k);
    const uint64_t bs2 = uint64_t{l.blockSamples} * l.blockSamples;
    directory_[k].resize(size_t{l.blocksPerSide} * l.blocksPerSide);
    for (BlockEntry& e : directory_[k]) {
      for (uint32_t c = 0; c < kChannelCount; ++c) {
        if (!((stored >> c) & 1u)) continue;
        const uint64_t off = getLe<uint64_t>(dir.data() + at);
        at += 8;
        e.offset[c] = off;
        uint64_t bytes = bs2 * kChannelBytes[c];
        if (compressed_) {
          bytes = e.bytes[c] = getLe<uint32_t>(dir.data() + at);
          at += 4;
          // A code is never empty, and never much larger than the raw samples it holds.
          const uint64_t side = l.blockSamples + 2;  // ring heights are the largest
          if (bytes == 0 || bytes > 2 * side * side * kChannelBytes[c] + 1024)
            fail("corrupt chart file (block size " + std::to_string(bytes) + " out of range at level " +
                 std::to_string(k) + ")");
        }
        if (off >= dirEnd && off <= fileSize && bytes <= fileSize - off) continue;
        if (off < dirEnd || off > (uint64_t{1} << 50))
          fail("corrupt chart file (block offset out of range at level " + std::to_string(k) + ")");
        fail("truncated chart file (" + std::to_string(fileSize) + " bytes; level " + std::to_string(k) +
             " blocks extend beyond the end)");
      }
    }
  }
}

const ChartFileReader::BlockEntry& ChartFileReader::block(uint32_t level, uint32_t bx, uint32_t by) const {
  const LevelLayout l = levelLayout(chartSize_, blockIntervals_, level);
  return directory_[level][size_t{by} * l.blocksPerSide + bx];
}

void ChartFileReader::locateWindow(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n, uint32_t& bx,
                                   uint32_t& by) const {
  if (level >= levels_)
    throw std::logic_error("ChartFileReader: level " + std::to_string(level) + " >= " + std::to_string(levels_) +
                           " in " + path_.string());
  const LevelLayout l = levelLayout(chartSize_, blockIntervals_, level);
  const uint32_t b = l.blockSamples - 1;
  auto pick = [&](uint32_t w0, const char* axis) {
    if (uint64_t{w0} + n >= l.samples)
      throw std::logic_error(std::string("ChartFileReader: window ") + axis + " [" + std::to_string(w0) + ", " +
                             std::to_string(uint64_t{w0} + n) + "] outside level " + std::to_string(level) + " of " +
                             path_.string());
    uint32_t blk = std::min(w0 / b, l.blocksPerSide - 1);
    if (w0 + n > blk * b + b)
      throw std::logic_error(std::string("ChartFileReader: window ") + axis + " [" + std::to_string(w0) + ", " +
                             std::to_string(w0 + n) + "] crosses a block boundary (block " + std::to_string(b) +
                             " intervals) at level " + std::to_string(level));
    return blk;
  };
  bx = pick(u0, "u");
  by = pick(v0, "v");
}

void ChartFileReader::readWindow(uint64_t first, uint64_t pitch, size_t rowBytes, uint32_t rows, void* out) const {
  auto* dst = static_cast<char*>(out);
  std::lock_guard<std::mutex> lock(mutex_);
  file_.clear();
  if (rowBytes == pitch) {
    // Whole rows: one contiguous read.
    file_.seekg(static_cast<std::streamoff>(first));
    file_.read(dst, static_cast<std::streamsize>(rowBytes * rows));
  } else {
    for (uint32_t r = 0; r < rows && file_; ++r) {
      file_.seekg(static_cast<std::streamoff>(first + r * pitch));
      file_.read(dst + r * rowBytes, static_cast<std::streamsize>(rowBytes));
    }
  }
  if (!file_) throw InputError(quoted(path_) + ": read failed (file truncated or changed while in use)");
}

namespace {
const char* channelName(ChartChannel c) {
  static constexpr const char* kNames[kChannelCount] = {"heights", "normals", "positions", "colours"};
  return kNames[c];
}
}  // namespace

void ChartFileReader::readCode(ChartChannel c, uint32_t level, uint32_t bx, uint32_t by,
                               std::vector<uint8_t>& code) const {
  const BlockEntry& e = block(level, bx, by);
  code.resize(e.bytes[c]);
  std::lock_guard<std::mutex> lock(mutex_);
  file_.clear();
  file_.seekg(static_cast<std::streamoff>(e.offset[c]));
  file_.read(reinterpret_cast<char*>(code.data()), static_cast<std::streamsize>(code.size()));
  if (!file_) throw InputError(quoted(path_) + ": read failed (file truncated or changed while in use)");
}

std::vector<uint8_t> ChartFileReader::readCodedBlock(ChartChannel c, uint32_t level, uint32_t bx, uint32_t by) const {
  if (!compressed_ || !hasChannel(c))
    throw std::logic_error("ChartFileReader: " + path_.string() + " has no coded blocks of channel " +
                           std::to_string(c));
  if (level >= storedLevels_ || std::max(bx, by) >= levelLayout(chartSize_, blockIntervals_, level).blocksPerSide)
    throw std::logic_error("ChartFileReader: " + path_.string() + " has no block (" + std::to_string(bx) + ", " +
                           std::to_string(by) + ") at level " + std::to_string(level));
  std::vector<uint8_t> code;
  readCode(c, level, bx, by, code);
  return code;
}

void ChartFileReader::decodeCode(ChartChannel c, uint32_t level, uint32_t bx, uint32_t by,
                                 std::vector<uint8_t>& out) const {
  const LevelLayout l = levelLayout(chartSize_, blockIntervals_, level);
  const uint32_t side = l.blockSamples + (frame_ && c == kChannelHeights ? 2 : 0);
  thread_local std::vector<uint8_t> code;
  readCode(c, level, bx, by, code);
  const size_t count = size_t{side} * side;
  out.resize(count * kChannelBytes[c]);
  void* to = out.data();
  try {
    switch (c) {
      case kChannelHeights: decodeHeights(code, side, {static_cast<float*>(to), count}); break;
      case kChannelPositions: decodePositions(code, side, {static_cast<float*>(to), 3 * count}); break;
      case kChannelNormals:
        if (borderNormals_)
          decodeBorderNormals(code, side, {static_cast<PackedNormal*>(to), count});
        else
          decodeNormals(code, side, {static_cast<PackedNormal*>(to), count});
        break;
      default: decodeColours(code, side, {static_cast<PackedColour*>(to), count}); break;
    }
  } catch (const CodecError& err) {
    throw InputError(quoted(path_) + ": level " + std::to_string(level) + " block (" + std::to_string(bx) + ", " +
                     std::to_string(by) + ") " + channelName(c) + ": " + err.what());
  }
}

const std::vector<uint8_t>& ChartFileReader::decodeBlock(ChartChannel c, uint32_t level, uint32_t bx,
                                                         uint32_t by) const {
  // The thread's last decoded block: a page's heights and then its derived normals decode once.
  struct Decoded {
    uint64_t serial = 0;
    uint32_t channel = 0, level = 0, bx = 0, by = 0;
    std::vector<uint8_t> samples;
  };
  thread_local Decoded last;
  if (last.serial == serial_ && last.channel == c && last.level == level && last.bx == bx && last.by == by)
    return last.samples;
  thread_local std::vector<uint8_t> samples, xyz;
  if (level >= storedLevels_) {
    // A level the file leaves out (flag 8): the stored level's samples (border normals with the
    // others derived from this level's own positions, as on any level).
    const uint32_t side = levelLayout(chartSize_, blockIntervals_, level).samples;
    subsampleStored(c, level, samples);
    if (borderNormals_ && c == kChannelNormals) {
      subsampleStored(kChannelPositions, level, xyz);
      geometryImageNormals(reinterpret_cast<const float*>(xyz.data()), side,
                           reinterpret_cast<PackedNormal*>(samples.data()));
    }
  } else {
    // Border normals: the block's positions first (the thread's last block when a page's
    // positions were just read), kept while the border decodes.
    if (borderNormals_ && c == kChannelNormals) xyz = decodeBlock(kChannelPositions, level, bx, by);
    if (level + 1 == storedLevels_ && storedLevels_ < levels_)
      samples = storedSource(c);  // the block the levels left out subsample: decoded once
    else
      decodeCode(c, level, bx, by, samples);
    if (borderNormals_ && c == kChannelNormals)
      geometryImageNormals(reinterpret_cast<const float*>(xyz.data()),
                           levelLayout(chartSize_, blockIntervals_, level).blockSamples,
                           reinterpret_cast<PackedNormal*>(samples.data()));
  }
  last.samples.swap(samples);
  last.serial = serial_;
  last.channel = c;
  last.level = level;
  last.bx = bx;
  last.by = by;
  return last.samples;
}

const std::vector<uint8_t>& ChartFileReader::storedSource(ChartChannel c) const {
  // The thread's last stored level's block of each channel, as coded (normals of flag 2: their
  // border alone), so that a chart's levels left out decode it once.
  struct Source {
    uint64_t serial = 0;
    std::vector<uint8_t> samples;
  };
  thread_local std::array<Source, kChannelCount> sources;
  Source& source = sources[c];
  if (source.serial != serial_) {
    source.serial = 0;
    decodeCode(c, storedLevels_ - 1, 0, 0, source.samples);
    source.serial = serial_;
  }
  return source.samples;
}

void ChartFileReader::subsampleStored(ChartChannel c, uint32_t level, std::vector<uint8_t>& out) const {
  const uint32_t s = storedLevels_ - 1, step = 1u << (level - s);
  const std::vector<uint8_t>& source = storedSource(c);
  const uint32_t from = levelLayout(chartSize_, blockIntervals_, s).samples;
  const uint32_t side = levelLayout(chartSize_, blockIntervals_, level).samples;
  out.resize(size_t{side} * side * kChannelBytes[c]);
  auto copy = [&](auto element) {
    using T = decltype(element);
    const auto* in = reinterpret_cast<const T*>(source.data());
    auto* to = reinterpret_cast<T*>(out.data());
    for (uint32_t v = 0; v < side; ++v)
      for (uint32_t u = 0; u < side; ++u) to[size_t{v} * side + u] = in[size_t{v * step} * from + u * step];
  };
  if (c == kChannelPositions)
    copy(glm::vec3{});
  else
    copy(PackedNormal{});  // normals and colours: 4 bytes a sample (a file of heights leaves none out)
}

void ChartFileReader::readChannel(ChartChannel c, uint32_t level, uint32_t u0, uint32_t v0, uint32_t n,
                                  void* out) const {
  const size_t elem = kChannelBytes[c];
  if (!hasChannel(c))
    throw std::logic_error("ChartFileReader: " + path_.string() + " has no channel " + std::to_string(c));
  uint32_t bx, by;
  locateWindow(level, u0, v0, n, bx, by);
  const LevelLayout l = levelLayout(chartSize_, blockIntervals_, level);
  const uint32_t b = l.blockSamples - 1;
  if (compressed_) {
    // The whole block decoded, then the window copied out of it (or its normals derived).
    const uint32_t du = u0 - bx * b, dv = v0 - by * b;
    if (frame_) {
      const uint32_t side = l.blockSamples + 2;
      const auto* ring = reinterpret_cast<const float*>(decodeBlock(kChannelHeights, level, bx, by).data()) +
                         size_t{dv + 1} * side + du + 1;
      if (c == kChannelNormals) {
        heightFieldNormals(ring, side, {level, u0, v0, n + 1, n + 1}, *frame_, static_cast<PackedNormal*>(out));
      } else {
        for (uint32_t r = 0; r <= n; ++r)
          std::memcpy(static_cast<float*>(out) + size_t{r} * (n + 1), ring + size_t{r} * side, size_t{n + 1} * elem);
      }
      return;
    }
    const std::vector<uint8_t>& decoded = decodeBlock(c, level, bx, by);
    const uint32_t bs = l.blockSamples;
    const size_t rowBytes = size_t{n + 1} * elem;
    for (uint32_t r = 0; r <= n; ++r)
      std::memcpy(static_cast<char*>(out) + r * rowBytes, decoded.data() + (size_t{dv + r} * bs + du) * elem, rowBytes);
    return;
  }
  const uint64_t pitch = uint64_t{l.blockSamples} * elem;
  readWindow(block(level, bx, by).offset[c] + uint64_t{v0 - by * b} * pitch + uint64_t{u0 - bx * b} * elem, pitch,
             size_t{n + 1} * elem, n + 1, out);
  if (kChannelIsFloat[c]) floatsFromLe(static_cast<float*>(out), size_t{n + 1} * (n + 1) * elem / sizeof(float));
}

void ChartFileReader::readHeights(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n, float* out) const {
  readChannel(kChannelHeights, level, u0, v0, n, out);
}

void ChartFileReader::readNormals(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n, PackedNormal* out) const {
  readChannel(kChannelNormals, level, u0, v0, n, out);
}

void ChartFileReader::readPositions(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n, glm::vec3* out) const {
  static_assert(sizeof(glm::vec3) == 3 * sizeof(float));
  readChannel(kChannelPositions, level, u0, v0, n, out);
}

void ChartFileReader::readColours(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n, PackedColour* out) const {
  readChannel(kChannelColours, level, u0, v0, n, out);
}

namespace {
template <typename T, typename ReadFn>
std::vector<T> assembleLevel(const LevelLayout& l, ReadFn read) {
  const uint32_t b = l.blockSamples - 1;
  std::vector<T> level(size_t{l.samples} * l.samples);
  std::vector<T> blk(size_t{l.blockSamples} * l.blockSamples);
  for (uint32_t by = 0; by < l.blocksPerSide; ++by)
    for (uint32_t bx = 0; bx < l.blocksPerSide; ++bx) {
      read(bx * b, by * b, b, blk.data());
      for (uint32_t v = 0; v < l.blockSamples; ++v)
        std::copy_n(blk.data() + size_t{v} * l.blockSamples, l.blockSamples,
                    level.data() + size_t{by * b + v} * l.samples + bx * b);
    }
  return level;
}
}  // namespace

std::vector<float> ChartFileReader::readLevelHeights(uint32_t level) const {
  if (level >= levels_) throw std::logic_error("ChartFileReader: level out of range");
  return assembleLevel<float>(
      levelLayout(chartSize_, blockIntervals_, level),
      [&](uint32_t u0, uint32_t v0, uint32_t n, float* out) { readHeights(level, u0, v0, n, out); });
}

std::vector<float> ChartFileReader::readHeightsWindow(uint32_t level, uint32_t u0, uint32_t v0, uint32_t n) const {
  if (level >= levels_) throw std::logic_error("ChartFileReader: level out of range");
  const LevelLayout l = levelLayout(chartSize_, blockIntervals_, level);
  const uint32_t b = l.blockSamples - 1;
  if (n == 0 || u0 % b || v0 % b || n % b || u0 + n > l.samples - 1 || v0 + n > l.samples - 1)
    throw std::logic_error("ChartFileReader: a window of whole blocks inside the level expected");
  const uint32_t side = n + 1;
  std::vector<float> out(size_t{side} * side);
  std::vector<float> blk(size_t{l.blockSamples} * l.blockSamples);
  for (uint32_t v = v0; v < v0 + n; v += b)
    for (uint32_t u = u0; u < u0 + n; u += b) {
      readHeights(level, u, v, b, blk.data());
      for (uint32_t r = 0; r <= b; ++r)
        std::copy_n(blk.data() + size_t{r} * l.blockSamples, l.blockSamples,
                    out.data() + size_t{v - v0 + r} * side + (u - u0));
    }
  return out;
}

std::vector<PackedNormal> ChartFileReader::readLevelNormals(uint32_t level) const {
  if (level >= levels_) throw std::logic_error("ChartFileReader: level out of range");
  return assembleLevel<PackedNormal>(
      levelLayout(chartSize_, blockIntervals_, level),
      [&](uint32_t u0, uint32_t v0, uint32_t n, PackedNormal* out) { readNormals(level, u0, v0, n, out); });
}

std::vector<glm::vec3> ChartFileReader::readLevelPositions(uint32_t level) const {
  if (level >= levels_) throw std::logic_error("ChartFileReader: level out of range");
  return assembleLevel<glm::vec3>(
      levelLayout(chartSize_, blockIntervals_, level),
      [&](uint32_t u0, uint32_t v0, uint32_t n, glm::vec3* out) { readPositions(level, u0, v0, n, out); });
}

std::vector<PackedColour> ChartFileReader::readLevelColours(uint32_t level) const {
  if (level >= levels_) throw std::logic_error("ChartFileReader: level out of range");
  return assembleLevel<PackedColour>(
      levelLayout(chartSize_, blockIntervals_, level),
      [&](uint32_t u0, uint32_t v0, uint32_t n, PackedColour* out) { readColours(level, u0, v0, n, out); });
}

StagedDirectory::StagedDirectory(const std::filesystem::path& target, const std::string& markerFile,
                                 const std::string& what)
    : target_(std::filesystem::absolute(target)), what_(what) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (target_.filename().empty()) target_ = target_.parent_path();
  if (fs::exists(target_, ec) && !fs::is_directory(target_, ec))
    throw InputError(target_.string() + ": exists and is not a directory");
  if (fs::is_directory(target_, ec) && !fs::is_empty(target_, ec) && !fs::exists(target_ / markerFile, ec))
    throw InputError(target_.string() + ": exists, is not empty and is not a gimlod " + what_ + "; not replacing it");
  // Missing parent folders are made, as `render -o` and `bench -o` make theirs.
  if (!fs::is_directory(target_.parent_path(), ec) &&
      (!fs::create_directories(target_.parent_path(), ec) || !fs::is_directory(target_.parent_path(), ec)))
    throw InputError(target_.string() + ": cannot create its parent directory" +
                     (ec ? ": " + ec.message() : std::string()));
  // A build killed by a signal (Ctrl-C, timeout, the OOM killer) cannot remove its staging
  // directory: remove those of processes that no longer exist before staging anew.
  {
    std::string prefix = ".";
    prefix += target_.filename().string();
    prefix += ".partial-";
    std::vector<fs::path> stale;
    for (fs::directory_iterator it(target_.parent_path(), ec), end; !ec && it != end; it.increment(ec)) {
      const std::string name = it->path().filename().string();
      if (name.compare(0, prefix.size(), prefix) != 0) continue;
      const long pid = std::strtol(name.c_str() + prefix.size(), nullptr, 10);
      if (pid > 0 && ::kill(pid_t(pid), 0) != 0 && errno == ESRCH) stale.push_back(it->path());
    }
    for (const fs::path& d : stale) fs::remove_all(d, ec);
    ec.clear();
  }
  std::random_device rd;
  char suffix[64];
  std::snprintf(suffix, sizeof(suffix), ".partial-%d-%x", int(::getpid()), unsigned(rd()));
  std::string name = ".";  // note: appended, not "." + ...: GCC 12 warns falsely (-Wrestrict) there
  name += target_.filename().string();
  name += suffix;
  path_ = target_.parent_path() / name;
  if (!fs::create_directory(path_, ec))
    throw InputError(target_.string() + ": cannot create the staging directory (" +
                     (ec ? ec.message() : std::string("already exists")) + ")");
  const std::lock_guard<std::mutex> lock(stagedMutex);
  stagedDirectories.push_back(directoryPrefix(path_));
}

StagedDirectory::~StagedDirectory() {
  forgetStagedDirectory(path_);
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
}

void StagedDirectory::commit() {
  namespace fs = std::filesystem;
  // Every file inside reaches the disk before the rename publishes them (their writers did not
  // flush them one by one).
  const int dir = ::open(path_.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir < 0 || (::syncfs(dir) != 0 && errno != EINVAL && errno != EROFS)) {
    const int err = errno;
    if (dir >= 0) ::close(dir);
    throw InputError(target_.string() + ": cannot flush the staged " + what_ + " (" + std::strerror(err) + ")");
  }
  ::close(dir);
  std::error_code ec;
  fs::path old;
  if (fs::exists(target_, ec)) {
    old = path_.string() + ".old";
    fs::rename(target_, old, ec);
    if (ec) throw InputError(target_.string() + ": cannot replace (" + ec.message() + ")");
  }
  fs::rename(path_, target_, ec);
  if (ec) {
    std::error_code ignored;
    if (!old.empty()) fs::rename(old, target_, ignored);
    throw InputError(target_.string() + ": cannot move the staged " + what_ + " into place (" + ec.message() + ")");
  }
  committed_ = true;
  if (!old.empty()) fs::remove_all(old, ec);
}

}  // namespace gimlod
