// Streaming mesh readers (PLY, OBJ, OFF, STL) with repair counting.
// Based on: Greg Turk, "The PLY Polygon File Format" (1994); the Wavefront OBJ and Geomview OFF
// format descriptions; the STL format of 3D Systems' "StereoLithography Interface Specification"
// (1989). Triangle strips are decoded as in OpenGL GL_TRIANGLE_STRIP (alternating winding).
#include "atlas/mesh/mesh_io.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <optional>
#include <type_traits>
#include <unordered_map>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <glm/common.hpp>

namespace gimlod {

namespace fs = std::filesystem;

void MeshBounds::extend(const glm::vec3& p) {
  min = glm::min(min, p);
  max = glm::max(max, p);
}

void MeshBounds::extend(const MeshBounds& b) {
  if (b.empty()) return;
  extend(b.min);
  extend(b.max);
}

const char* meshFormatName(MeshFormat f) {
  switch (f) {
    case MeshFormat::kPly: return "ply";
    case MeshFormat::kObj: return "obj";
    case MeshFormat::kOff: return "off";
    case MeshFormat::kStl: return "stl";
  }
  return "?";
}

namespace {

constexpr size_t kBufferBytes = size_t{1} << 20;
constexpr uint64_t kMaxVertices = uint64_t{kNoVertex} - 1;
constexpr size_t kMaxWarnings = 16;
const glm::u8vec4 kWhite{255, 255, 255, 255};

[[noreturn]] void fail(const fs::path& file, const std::string& what) {
  throw InputError(file.string() + ": " + what);
}

std::string lower(std::string_view s) {
  std::string r(s);
  for (char& c : r) c = char(std::tolower(static_cast<unsigned char>(c)));
  return r;
}

void warn(MeshReadStats& stats, std::string what) {
  if (stats.warnings.size() < kMaxWarnings) stats.warnings.push_back(std::move(what));
}

// ---- buffered input ---------------------------------------------------------------------------

// Sequential reads through one large buffer, for binary records and text lines alike.
class FileBuffer {
 public:
  explicit FileBuffer(const fs::path& path, size_t capacity = kBufferBytes) : path_(path) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) fail(path, std::string("cannot open: ") + std::strerror(errno));
    struct stat st {};
    if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
      ::close(fd_);
      fail(path, "not a regular file");
    }
    size_ = static_cast<uint64_t>(st.st_size);
    ::posix_fadvise(fd_, 0, 0, POSIX_FADV_SEQUENTIAL);
    capacity_ = std::max<size_t>(capacity, 4096);
    buf_.reset(new uint8_t[capacity_]);  // note: not zeroed; only bytes read are used
  }
  ~FileBuffer() { ::close(fd_); }
  FileBuffer(const FileBuffer&) = delete;
  FileBuffer& operator=(const FileBuffer&) = delete;

  const fs::path& path() const { return path_; }
  uint64_t size() const { return size_; }
  size_t capacity() const { return capacity_; }
  // Absolute file offset of data().
  uint64_t offset() const { return consumed_ + cur_; }
  uint64_t remaining() const { return size_ - std::min(size_, offset()); }
  uint64_t lineNumber() const { return line_; }
  // The last line nextLine returned ended the file without a line break (a cut-off text file).
  bool lineUnterminated() const { return unterminated_; }
  const uint8_t* data() const { return buf_.get() + cur_; }
  size_t available() const { return end_ - cur_; }

  // Makes n contiguous bytes available at data() (n <= capacity); false if the file ends first.
  bool ensure(size_t n) { return end_ - cur_ >= n || fill(n); }
  void advance(size_t n) { cur_ += n; }
  // Skips n bytes; false if the file ends first.
  bool skip(uint64_t n) {
    while (n > 0) {
      if (!ensure(1)) return false;
      const size_t step = static_cast<size_t>(std::min<uint64_t>(n, available()));
      cur_ += step;
      n -= step;
    }
    return true;
  }

  // Next text line without its terminator ("\n" or "\r\n"); false at the end of the file.
  bool nextLine(std::string_view& line) {
    size_t scanned = 0;
    for (;;) {
      const uint8_t* b = buf_.get() + cur_;
      const size_t avail = end_ - cur_;
      if (const void* nl = std::memchr(b + scanned, '\n', avail - scanned)) {
        const size_t len = static_cast<size_t>(static_cast<const uint8_t*>(nl) - b);
        setLine(line, b, len);
        cur_ += len + 1;
        return true;
      }
      scanned = avail;
      if (eof_) {
        if (avail == 0) return false;
        setLine(line, b, avail);
        cur_ = end_;
        unterminated_ = true;
        return true;
      }
      if (avail == capacity_)
        fail(path_, "line " + std::to_string(line_ + 1) + " is longer than " +
                        std::to_string(capacity_ >> 20) + " MiB (binary data in a text file?)");
      fill(avail + 1);
    }
  }

 private:
  void setLine(std::string_view& line, const uint8_t* b, size_t len) {
    if (len > 0 && b[len - 1] == '\r') --len;
    line = std::string_view(reinterpret_cast<const char*>(b), len);
    ++line_;
  }
  bool fill(size_t n) {
    if (cur_ > 0) {
      std::memmove(buf_.get(), buf_.get() + cur_, end_ - cur_);
      consumed_ += cur_;
      end_ -= cur_;
      cur_ = 0;
    }
    while (!eof_ && end_ < capacity_ && end_ < n) {
      const ssize_t r = ::read(fd_, buf_.get() + end_, capacity_ - end_);
      if (r < 0) {
        if (errno == EINTR) continue;
        fail(path_, std::string("read failed: ") + std::strerror(errno));
      }
      if (r == 0) eof_ = true;
      end_ += static_cast<size_t>(r);
    }
    return end_ >= n;
  }

  fs::path path_;
  int fd_ = -1;
  uint64_t size_ = 0;
  std::unique_ptr<uint8_t[]> buf_;
  size_t capacity_ = 0;
  size_t cur_ = 0, end_ = 0;
  uint64_t consumed_ = 0;  // file bytes before buf_[0]
  uint64_t line_ = 0;
  bool eof_ = false;
  bool unterminated_ = false;
};

// Appended to a parse error on a text line: says so when that line is the file's last and has no
// line break, i.e. the file was probably cut off there.
std::string cutShort(const FileBuffer& f) {
  return f.lineUnterminated() ? " (truncated: the file ends in the middle of this line)" : "";
}

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

// Whitespace-separated tokens of one line.
struct Tokens {
  std::string_view s;
  size_t pos = 0;
  bool next(std::string_view& tok) {
    while (pos < s.size() && isSpace(s[pos])) ++pos;
    if (pos >= s.size()) return false;
    const size_t b = pos;
    while (pos < s.size() && !isSpace(s[pos])) ++pos;
    tok = s.substr(b, pos - b);
    return true;
  }
};

// Tokens across lines (PLY ASCII bodies, where line breaks carry no meaning).
class TokenReader {
 public:
  explicit TokenReader(FileBuffer& f) : f_(f) {}
  bool next(std::string_view& tok) {
    for (;;) {
      if (t_.next(tok)) return true;
      std::string_view line;
      if (!f_.nextLine(line)) return false;
      t_ = Tokens{line, 0};
    }
  }
 private:
  FileBuffer& f_;
  Tokens t_;
};

// Parses a whole token as a number. Out-of-range values become +-inf (or 0 for underflow), so
// they are repaired like other non-finite coordinates.
bool parseDouble(std::string_view tok, double& v) {
  const char* b = tok.data();
  const char* e = b + tok.size();
  if (b != e && *b == '+') ++b;
  auto [ptr, ec] = std::from_chars(b, e, v);
  if (ec == std::errc::result_out_of_range) {
    v = std::strtod(std::string(tok).c_str(), nullptr);
    return true;
  }
  return ec == std::errc() && ptr == e;
}

bool parseInt(std::string_view tok, int64_t& v) {
  const char* b = tok.data();
  const char* e = b + tok.size();
  if (b != e && *b == '+') ++b;
  auto [ptr, ec] = std::from_chars(b, e, v);
  return ec == std::errc() && ptr == e;
}

std::string shown(std::string_view tok) {
  std::string s(tok.substr(0, 40));
  for (char& c : s)
    if (static_cast<unsigned char>(c) < 32 || static_cast<unsigned char>(c) > 126) c = '?';
  return "'" + s + (tok.size() > 40 ? "...'" : "'");
}

// ---- the vertex array and the triangle emitter -------------------------------------------------

struct VertexArray {
  std::vector<glm::vec3> pos;
  std::vector<glm::u8vec4> col;  // empty or pos.size()
};

bool finite(const glm::vec3& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

// Exactly zero area: the cross product of two edges (computed in double) vanishes.
bool zeroArea(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
  const double ux = double(b.x) - a.x, uy = double(b.y) - a.y, uz = double(b.z) - a.z;
  const double vx = double(c.x) - a.x, vy = double(c.y) - a.y, vz = double(c.z) - a.z;
  return uy * vz - uz * vy == 0.0 && uz * vx - ux * vz == 0.0 && ux * vy - uy * vx == 0.0;
}

// A canonical triangle key. {0, 0} marks an empty slot; real keys never are (an index key has
// its largest index, >= 2, in b; position keys are forced non-zero).
struct DupKey {
  uint64_t a = 0, b = 0;
  bool operator==(const DupKey&) const = default;
  bool isEmpty() const { return (a | b) == 0; }
};

uint64_t mix64(uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  x ^= x >> 31;
  return x;
}

// Open-addressing set of 128-bit keys with a memory bound (load factor <= 0.7). Tables are
// zero pages from mmap (no fill pass), with transparent huge pages asked for: the set is probed
// at random, so callers prefetch slots ahead of use.
class DuplicateSet {
 public:
  explicit DuplicateSet(uint64_t maxBytes) : maxBytes_(maxBytes) {}
  ~DuplicateSet() { release(slots_, capacity_); }
  DuplicateSet(const DuplicateSet&) = delete;
  DuplicateSet& operator=(const DuplicateSet&) = delete;

  // Sizes the table for about n keys (within the bound), so that it need not grow.
  void reserve(uint64_t n) {
    uint64_t slots = uint64_t{1} << 12;
    while (slots * 7 < n * 10 && slots < (uint64_t{1} << 40)) slots *= 2;
    while (maxBytes_ != 0 && slots * sizeof(DupKey) > maxBytes_ && slots > 1) slots /= 2;
    if (slots > capacity_ && !full_) allocate(static_cast<size_t>(slots));
  }
  void prefetch(const DupKey& k) const {
    if (capacity_ != 0) __builtin_prefetch(slots_ + slot(k));
  }
  // True if k was seen before; otherwise records it (while there is room).
  bool testAndInsert(const DupKey& k) {
    if (capacity_ == 0 && (full_ || !allocate(size_t{1} << 12))) {
      full_ = true;
      return false;
    }
    size_t i = slot(k);
    while (!slots_[i].isEmpty()) {
      if (slots_[i] == k) return true;
      i = (i + 1) & mask_;
    }
    if (full_) return false;
    if ((count_ + 1) * 10 > capacity_ * 7) {
      if (!allocate(capacity_ * 2)) {
        full_ = true;
        return false;
      }
      i = slot(k);
      while (!slots_[i].isEmpty()) i = (i + 1) & mask_;
    }
    slots_[i] = k;
    ++count_;
    return false;
  }
  bool complete() const { return !full_; }
  uint64_t bytes() const { return capacity_ * sizeof(DupKey); }

 private:
  size_t slot(const DupKey& k) const { return mix64(k.a ^ mix64(k.b)) & mask_; }
  static void release(DupKey* p, size_t n) {
    if (p) ::munmap(p, n * sizeof(DupKey));
  }
  bool allocate(size_t n) {
    const size_t bytes = n * sizeof(DupKey);
    if (maxBytes_ != 0 && bytes > maxBytes_) return false;
    void* mem = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (mem == MAP_FAILED) return false;
    if (bytes >= (size_t{2} << 20)) ::madvise(mem, bytes, MADV_HUGEPAGE);
    DupKey* old = slots_;
    const size_t oldCapacity = capacity_;
    slots_ = static_cast<DupKey*>(mem);
    capacity_ = n;
    mask_ = n - 1;
    for (size_t j = 0; j < oldCapacity; ++j) {
      const DupKey& k = old[j];
      if (k.isEmpty()) continue;
      size_t i = slot(k);
      while (!slots_[i].isEmpty()) i = (i + 1) & mask_;
      slots_[i] = k;
    }
    release(old, oldCapacity);
    return true;
  }
  DupKey* slots_ = nullptr;
  size_t capacity_ = 0, mask_ = 0, count_ = 0;
  uint64_t maxBytes_;
  bool full_ = false;
};

// Checks candidate triangles, counts repairs, and delivers chunks to the sink. Duplicate checks
// run in batches: each candidate's slot is prefetched when it arrives and tested kBatch
// candidates later, so the table's cache misses overlap.
class Emitter {
 public:
  Emitter(TriangleSink& sink, const MeshReadOptions& o, MeshReadStats& stats)
      : sink_(sink), stats_(stats), dedupe_(o.removeDuplicates), dup_(o.duplicateSetBytes),
        chunkSize_(o.chunkTriangles) {
  }
  void setVertices(const VertexArray* va) { va_ = va; }
  void begin(const MeshInfo& info) {
    if (begun_) return;
    begun_ = true;
    if (dedupe_) dup_.reserve(info.triangleEstimate);
    chunk_.reserve(std::min<size_t>(std::min<uint64_t>(chunkSize_, info.triangleEstimate + 1),
                                    size_t{1} << 20) + kBatch);
    sink_.begin(info);
  }

  // Indices must be < the vertex count (checked by the caller, who knows the face number).
  void indexed(uint32_t a, uint32_t b, uint32_t c, bool inStrip) {
    ++stats_.trianglesRead;
    const glm::vec3& pa = va_->pos[a];
    const glm::vec3& pb = va_->pos[b];
    const glm::vec3& pc = va_->pos[c];
    if (!finite(pa) || !finite(pb) || !finite(pc)) {
      ++stats_.droppedNonFinite;
      return;
    }
    if (a == b || b == c || a == c || zeroArea(pa, pb, pc)) {
      ++stats_.droppedDegenerate;
      if (inStrip) ++stats_.droppedStripDegenerate;
      return;
    }
    MeshTriangle& t = chunk_.emplace_back();
    t.p = {pa, pb, pc};
    if (va_->col.empty()) t.c = {kWhite, kWhite, kWhite};
    else t.c = {va_->col[a], va_->col[b], va_->col[c]};
    t.v = {a, b, c};
    if (!dedupe_) return accept();
    uint32_t s[3] = {a, b, c};
    if (s[0] > s[1]) std::swap(s[0], s[1]);
    if (s[1] > s[2]) std::swap(s[1], s[2]);
    if (s[0] > s[1]) std::swap(s[0], s[1]);
    pend(DupKey{(uint64_t{s[0]} << 32) | s[1], s[2]});
  }

  // A triangle given by positions (STL).
  void soup(const glm::vec3& pa, const glm::vec3& pb, const glm::vec3& pc) {
    ++stats_.trianglesRead;
    if (!finite(pa) || !finite(pb) || !finite(pc)) {
      ++stats_.droppedNonFinite;
      return;
    }
    if (zeroArea(pa, pb, pc)) {
      ++stats_.droppedDegenerate;
      return;
    }
    MeshTriangle& t = chunk_.emplace_back();
    t.p = {pa, pb, pc};
    t.c = {kWhite, kWhite, kWhite};
    t.v = {kNoVertex, kNoVertex, kNoVertex};
    if (!dedupe_) return accept();
    // Key: the three positions' bit patterns (-0 as +0), sorted, hashed to 128 bits.
    std::array<uint64_t, 3> w;
    for (int i = 0; i < 3; ++i) {
      const glm::vec3& p = t.p[i];
      const uint64_t x = std::bit_cast<uint32_t>(p.x + 0.0f);
      const uint64_t y = std::bit_cast<uint32_t>(p.y + 0.0f);
      const uint64_t z = std::bit_cast<uint32_t>(p.z + 0.0f);
      w[i] = mix64((x << 32 | y) ^ mix64(z + 0x9e3779b97f4a7c15ull)) ^ z * 0xff51afd7ed558ccdull;
    }
    std::sort(w.begin(), w.end());
    DupKey k{mix64(w[0] ^ mix64(w[1] ^ mix64(w[2]))),
             mix64(w[2] + 0x632be59bd9b4e019ull) ^ mix64(w[0] + 3 * w[1])};
    if (k.isEmpty()) k.b = 1;
    pend(k);
  }

  void flush() {
    resolve();
    if (!chunk_.empty()) sink_.consume(chunk_.data(), chunk_.size());
    chunk_.clear();
  }
  void finish() {
    flush();
    stats_.duplicateCheckComplete = dup_.complete();
    stats_.duplicateSetBytes = dup_.bytes();
    if (!dup_.complete())
      warn(stats_, "the duplicate-triangle set reached its memory bound; later duplicates are "
                   "only caught against earlier triangles (the per-cell stage catches the rest)");
  }

 private:
  static constexpr size_t kBatch = 32;

  // The last candidate in chunk_ awaits its duplicate check.
  void pend(const DupKey& k) {
    dup_.prefetch(k);
    keys_[pending_++] = k;
    if (pending_ == kBatch || chunk_.size() >= chunkSize_) resolve();
  }
  // Tests the pending candidates (the tail of chunk_) in order and drops the duplicates.
  void resolve() {
    if (pending_ == 0) return;
    size_t out = chunk_.size() - pending_;
    const size_t first = out;
    for (size_t i = 0; i < pending_; ++i) {
      if (dup_.testAndInsert(keys_[i])) {
        ++stats_.droppedDuplicate;
        continue;
      }
      if (out != first + i) chunk_[out] = chunk_[first + i];
      count(chunk_[out++]);
    }
    chunk_.resize(out);
    pending_ = 0;
    if (chunk_.size() >= chunkSize_) flushReady();
  }
  void accept() {
    count(chunk_.back());
    if (chunk_.size() >= chunkSize_) flushReady();
  }
  void count(const MeshTriangle& t) {
    ++stats_.trianglesOut;
    stats_.bounds.extend(t.p[0]);
    stats_.bounds.extend(t.p[1]);
    stats_.bounds.extend(t.p[2]);
  }
  // Delivers the checked triangles (no candidate is pending here).
  void flushReady() {
    if (!chunk_.empty()) sink_.consume(chunk_.data(), chunk_.size());
    chunk_.clear();
  }

  TriangleSink& sink_;
  MeshReadStats& stats_;
  bool dedupe_;
  DuplicateSet dup_;
  size_t chunkSize_;
  const VertexArray* va_ = nullptr;
  std::vector<MeshTriangle> chunk_;
  std::array<DupKey, kBatch> keys_;
  size_t pending_ = 0;
  bool begun_ = false;
};

// Turns a stream of polygon corners (fan) or strip indices into triangles.
class FanDecoder {
 public:
  void start() { n_ = 0; }
  void push(uint32_t i, Emitter& e) {
    if (n_ == 0) first_ = i;
    else if (n_ >= 2) e.indexed(first_, prev_, i, false);
    prev_ = i;
    ++n_;
  }
  uint64_t corners() const { return n_; }

 private:
  uint32_t first_ = 0, prev_ = 0;
  uint64_t n_ = 0;
};

class StripDecoder {
 public:
  // Returns true if the index started a new strip.
  bool push(uint32_t i, Emitter& e) {
    const bool started = n_ == 0;
    if (n_ >= 2) {
      if ((n_ - 2) % 2 == 0) e.indexed(a_, b_, i, true);
      else e.indexed(b_, a_, i, true);
    }
    a_ = b_;
    b_ = i;
    ++n_;
    return started;
  }
  void restart() { n_ = 0; }

 private:
  uint32_t a_ = 0, b_ = 0;
  uint64_t n_ = 0;
};

void checkVertexBytes(const fs::path& path, uint64_t vertices, bool colours,
                      const MeshReadOptions& o, const std::string& where = "") {
  if (vertices > kMaxVertices)
    fail(path, std::to_string(vertices) + " vertices: more than the supported " +
                   std::to_string(kMaxVertices));
  const uint64_t bytes = vertices * (colours ? 16 : 12);
  if (o.maxVertexBytes != 0 && bytes > o.maxVertexBytes)
    fail(path, where + "the vertex array of " + std::to_string(vertices) + " vertices needs " +
                   std::to_string(bytes) + " bytes, more than the " +
                   std::to_string(o.maxVertexBytes) +
                   " bytes allowed (raise the memory cap, or convert the mesh to binary STL, which "
                   "streams without a vertex array)");
}

glm::u8vec4 colourFromFloat(double r, double g, double b, double a) {
  auto c = [](double v) {
    if (!(v > 0)) return uint8_t{0};
    return v >= 1 ? uint8_t{255} : static_cast<uint8_t>(std::lround(v * 255.0));
  };
  return {c(r), c(g), c(b), c(a)};
}

glm::u8vec4 colourFromInt(double r, double g, double b, double a) {
  auto c = [](double v) {
    if (!(v > 0)) return uint8_t{0};
    return v >= 255 ? uint8_t{255} : static_cast<uint8_t>(std::lround(v));
  };
  return {c(r), c(g), c(b), c(a)};
}

// ---- PLY --------------------------------------------------------------------------------------

enum class PlyType : uint8_t { kI8, kU8, kI16, kU16, kI32, kU32, kF32, kF64 };

size_t plySize(PlyType t) {
  switch (t) {
    case PlyType::kI8: case PlyType::kU8: return 1;
    case PlyType::kI16: case PlyType::kU16: return 2;
    case PlyType::kI32: case PlyType::kU32: case PlyType::kF32: return 4;
    case PlyType::kF64: return 8;
  }
  return 0;
}

bool plyIsInt(PlyType t) { return t != PlyType::kF32 && t != PlyType::kF64; }

bool plyTypeFromName(std::string_view s, PlyType& t) {
  static const std::pair<const char*, PlyType> kNames[] = {
      {"char", PlyType::kI8},    {"int8", PlyType::kI8},     {"uchar", PlyType::kU8},
      {"uint8", PlyType::kU8},   {"short", PlyType::kI16},   {"int16", PlyType::kI16},
      {"ushort", PlyType::kU16}, {"uint16", PlyType::kU16},  {"int", PlyType::kI32},
      {"int32", PlyType::kI32},  {"uint", PlyType::kU32},    {"uint32", PlyType::kU32},
      {"float", PlyType::kF32},  {"float32", PlyType::kF32}, {"double", PlyType::kF64},
      {"float64", PlyType::kF64}};
  for (const auto& [n, v] : kNames)
    if (s == n) {
      t = v;
      return true;
    }
  return false;
}

template <typename U>
U loadSwapped(const uint8_t* p, bool swap) {
  U u;
  std::memcpy(&u, p, sizeof u);
  if (swap) {
    if constexpr (sizeof(U) == 2) u = __builtin_bswap16(u);
    else if constexpr (sizeof(U) == 4) u = __builtin_bswap32(u);
    else u = __builtin_bswap64(u);
  }
  return u;
}

// One PLY scalar as T: double reads every type; int64_t reads the integer types (float index
// types are rejected in the header, and read as 0 here).
template <typename T>
T plyValue(const uint8_t* p, PlyType t, bool swap) {
  switch (t) {
    case PlyType::kI8: return static_cast<int8_t>(p[0]);
    case PlyType::kU8: return p[0];
    case PlyType::kI16: return static_cast<int16_t>(loadSwapped<uint16_t>(p, swap));
    case PlyType::kU16: return loadSwapped<uint16_t>(p, swap);
    case PlyType::kI32: return static_cast<int32_t>(loadSwapped<uint32_t>(p, swap));
    case PlyType::kU32: return loadSwapped<uint32_t>(p, swap);
    case PlyType::kF32:
      if constexpr (std::is_floating_point_v<T>) return std::bit_cast<float>(loadSwapped<uint32_t>(p, swap));
      return 0;
    case PlyType::kF64:
      if constexpr (std::is_floating_point_v<T>) return std::bit_cast<double>(loadSwapped<uint64_t>(p, swap));
      return 0;
  }
  return 0;
}

double plyScalar(const uint8_t* p, PlyType t, bool swap) { return plyValue<double>(p, t, swap); }
int64_t plyInt(const uint8_t* p, PlyType t, bool swap) { return plyValue<int64_t>(p, t, swap); }

struct PlyProp {
  std::string name;
  PlyType type = PlyType::kF32;
  bool list = false;
  PlyType countType = PlyType::kU8;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProp> props;
  // Role of this element.
  enum Kind { kOther, kVertex, kFace, kStrips } kind = kOther;
  int indexProp = -1;  // the vertex index list of faces / strips
};

struct PlyHeader {
  enum Encoding { kAscii, kLittle, kBig } encoding = kAscii;
  std::vector<PlyElement> elements;
};

// Minimum body bytes of an element instance (binary: fixed parts; ASCII: "0 " per value).
uint64_t plyMinInstanceBytes(const PlyElement& e, bool ascii) {
  uint64_t n = 0;
  for (const PlyProp& p : e.props) n += ascii ? 2 : plySize(p.list ? p.countType : p.type);
  return n;
}

PlyHeader readPlyHeader(FileBuffer& f) {
  const fs::path& path = f.path();
  std::string_view line;
  if (!f.nextLine(line) || line != "ply")
    fail(path, "not a PLY file (the first line is not 'ply')");
  PlyHeader h;
  bool haveFormat = false, done = false;
  while (!done) {
    if (f.offset() > (uint64_t{1} << 20))
      fail(path, "bad PLY header: no 'end_header' in the first MiB");
    if (!f.nextLine(line)) fail(path, "bad PLY header: the file ends before 'end_header'");
    if (f.lineUnterminated() && line != "end_header")
      fail(path, "bad PLY header: the file ends before 'end_header', in the middle of header line " +
                     std::to_string(f.lineNumber()) + " (truncated)");
    const std::string where = "PLY header line " + std::to_string(f.lineNumber());
    Tokens t{line};
    std::string_view kw, a, b, c, d;
    if (!t.next(kw)) continue;
    if (kw == "comment" || kw == "obj_info") continue;
    if (kw == "end_header") {
      done = true;
    } else if (kw == "format") {
      if (!t.next(a) || !t.next(b)) fail(path, where + ": bad format line");
      if (a == "ascii") h.encoding = PlyHeader::kAscii;
      else if (a == "binary_little_endian") h.encoding = PlyHeader::kLittle;
      else if (a == "binary_big_endian") h.encoding = PlyHeader::kBig;
      else fail(path, where + ": unsupported PLY format " + shown(a));
      if (b != "1.0" && b != "1") fail(path, where + ": unsupported PLY version " + shown(b));
      haveFormat = true;
    } else if (kw == "element") {
      int64_t n = -1;
      if (!t.next(a) || !t.next(b))
        fail(path, where + ": bad element line (want 'element NAME COUNT')");
      if (!parseInt(b, n) || n < 0) {
        const bool digits = !b.empty() && b.find_first_not_of("0123456789") == std::string_view::npos;
        fail(path, where + ": bad element line (want 'element NAME COUNT'): the count " + shown(b) +
                       (digits ? " is too large" : " is not a non-negative integer"));
      }
      PlyElement e;
      e.name = std::string(a);
      e.count = static_cast<uint64_t>(n);
      h.elements.push_back(std::move(e));
    } else if (kw == "property") {
      if (h.elements.empty()) fail(path, where + ": property before any element");
      PlyProp p;
      if (!t.next(a)) fail(path, where + ": bad property line");
      if (a == "list") {
        if (!t.next(b) || !t.next(c) || !t.next(d)) fail(path, where + ": bad list property line");
        p.list = true;
        if (!plyTypeFromName(b, p.countType))
          fail(path, where + ": unknown PLY property type " + shown(b));
        if (!plyTypeFromName(c, p.type))
          fail(path, where + ": unknown PLY property type " + shown(c));
        if (!plyIsInt(p.countType))
          fail(path, where + ": list count type " + shown(b) + " is not an integer type");
        p.name = std::string(d);
      } else {
        if (!plyTypeFromName(a, p.type))
          fail(path, where + ": unknown PLY property type " + shown(a));
        if (!t.next(b)) fail(path, where + ": property without a name");
        p.name = std::string(b);
      }
      h.elements.back().props.push_back(std::move(p));
    } else {
      fail(path, where + ": unknown PLY header keyword " + shown(kw));
    }
  }
  if (!haveFormat) fail(path, "bad PLY header: no 'format' line");

  // Roles, order, and a size check before anything is allocated.
  int vertexAt = -1, firstFaceAt = -1;
  for (size_t i = 0; i < h.elements.size(); ++i) {
    PlyElement& e = h.elements[i];
    if (e.name == "vertex") {
      if (vertexAt >= 0) fail(path, "bad PLY header: two vertex elements");
      e.kind = PlyElement::kVertex;
      vertexAt = static_cast<int>(i);
      for (const char* axis : {"x", "y", "z"}) {
        auto it = std::find_if(e.props.begin(), e.props.end(),
                               [&](const PlyProp& p) { return p.name == axis; });
        if (it == e.props.end())
          fail(path, std::string("PLY vertex element has no '") + axis + "'");
        if (it->list) fail(path, std::string("PLY vertex property '") + axis + "' is a list");
      }
    } else if (e.name == "face" || e.name == "tristrips") {
      e.kind = e.name == "face" ? PlyElement::kFace : PlyElement::kStrips;
      for (size_t k = 0; k < e.props.size(); ++k)
        if (e.props[k].name == "vertex_indices" ||
            (e.kind == PlyElement::kFace && e.props[k].name == "vertex_index"))
          e.indexProp = static_cast<int>(k);
      if (e.indexProp < 0)
        fail(path, "PLY element '" + e.name + "' has no 'vertex_indices' property");
      const PlyProp& ip = e.props[static_cast<size_t>(e.indexProp)];
      if (!ip.list || !plyIsInt(ip.type))
        fail(path, "PLY property '" + e.name + "." + ip.name + "' must be a list of integers");
      if (firstFaceAt < 0) firstFaceAt = static_cast<int>(i);
    }
  }
  if (vertexAt < 0) fail(path, "PLY file has no vertex element");
  if (firstFaceAt < 0)
    fail(path, "PLY file has no face or tristrips element (a point cloud, not a mesh)");
  if (firstFaceAt < vertexAt)
    fail(path, "PLY faces come before the vertices (not supported: faces are streamed)");

  const bool ascii = h.encoding == PlyHeader::kAscii;
  const uint64_t body = f.remaining();
  uint64_t need = 0;
  for (const PlyElement& e : h.elements) {
    const uint64_t per = plyMinInstanceBytes(e, ascii);
    if (per != 0 && e.count > (body - std::min(need, body)) / per + 1)
      fail(path, "the header declares " + std::to_string(e.count) + " '" + e.name +
                     "' elements, needing at least " + std::to_string(e.count) + " x " +
                     std::to_string(per) + " bytes, but only " + std::to_string(body) +
                     " bytes follow the header (truncated or corrupt file)");
    need += e.count * per;
  }
  if (need > body + (ascii ? 1 : 0))
    fail(path, "truncated: the header's elements need at least " + std::to_string(need) +
                   " bytes but only " + std::to_string(body) + " follow the header");
  return h;
}

std::string plyFormatName(const PlyHeader& h) {
  switch (h.encoding) {
    case PlyHeader::kAscii: return "PLY ASCII";
    case PlyHeader::kLittle: return "PLY binary little-endian";
    case PlyHeader::kBig: return "PLY binary big-endian";
  }
  return "PLY";
}

struct PlyVertexLayout {
  int x = -1, y = -1, z = -1, r = -1, g = -1, b = -1, a = -1;
  bool colours() const { return r >= 0 && g >= 0 && b >= 0; }
};

PlyVertexLayout plyVertexLayout(const PlyElement& e) {
  PlyVertexLayout l;
  for (size_t i = 0; i < e.props.size(); ++i) {
    const std::string& n = e.props[i].name;
    if (e.props[i].list) continue;
    const int k = static_cast<int>(i);
    if (n == "x") l.x = k;
    else if (n == "y") l.y = k;
    else if (n == "z") l.z = k;
    else if (n == "red" || n == "diffuse_red" || n == "r") l.r = k;
    else if (n == "green" || n == "diffuse_green" || n == "g") l.g = k;
    else if (n == "blue" || n == "diffuse_blue" || n == "b") l.b = k;
    else if (n == "alpha" || n == "diffuse_alpha" || n == "a") l.a = k;
  }
  return l;
}

glm::u8vec4 plyColour(const double* v, const PlyElement& e, const PlyVertexLayout& l) {
  const bool isFloat = !plyIsInt(e.props[static_cast<size_t>(l.r)].type);
  const bool wide = e.props[static_cast<size_t>(l.r)].type == PlyType::kU16 ||
                    e.props[static_cast<size_t>(l.r)].type == PlyType::kI16;
  const double scale = wide ? 1.0 / 257.0 : 1.0;
  const double alpha = l.a >= 0 ? v[l.a] : (isFloat ? 1.0 : 255.0 / scale);
  if (isFloat) return colourFromFloat(v[l.r], v[l.g], v[l.b], alpha);
  return colourFromInt(v[l.r] * scale, v[l.g] * scale, v[l.b] * scale, alpha * scale);
}

class PlyReader {
 public:
  PlyReader(FileBuffer& f, Emitter& emit, VertexArray& va, MeshReadStats& stats,
            const MeshReadOptions& o)
      : f_(f), path_(f.path()), emit_(emit), va_(va), stats_(stats), o_(o), tr_(f) {}

  // Reads the header and the vertex element; with verticesOnly, stops there.
  void run(bool verticesOnly) {
    h_ = readPlyHeader(f_);
    ascii_ = h_.encoding == PlyHeader::kAscii;
    swap_ = (h_.encoding == PlyHeader::kBig) != (std::endian::native == std::endian::big);
    MeshInfo& info = stats_.info;
    info.format = MeshFormat::kPly;
    info.formatName = plyFormatName(h_);
    for (const PlyElement& e : h_.elements) {
      if (e.kind == PlyElement::kVertex) {
        info.vertices = e.count;
        info.hasColours = plyVertexLayout(e).colours();
      } else if (e.kind == PlyElement::kFace) {
        info.faces += e.count;
        info.triangleEstimate += e.count;
      } else if (e.kind == PlyElement::kStrips) {
        info.faces += e.count;
        info.triangleEstimate += 2 * info.vertices;  // Euler: a closed mesh has ~2V triangles
      }
    }
    bool begun = false;
    for (size_t i = 0; i < h_.elements.size(); ++i) {
      const PlyElement& e = h_.elements[i];
      if (e.kind == PlyElement::kVertex) {
        readVertices(e);
        if (verticesOnly) return;
      } else if (e.kind == PlyElement::kFace || e.kind == PlyElement::kStrips) {
        if (!begun) {
          emit_.begin(info);
          begun = true;
        }
        readFaces(e);
      } else {
        skipElement(e);
      }
    }
    checkTrailing();
  }

 private:
  std::string elementWhere(const PlyElement& e, uint64_t i) const {
    return "'" + e.name + "' element " + std::to_string(i);
  }
  [[noreturn]] void truncated(const PlyElement& e, uint64_t i) {
    fail(path_, "truncated: the file ends in " + elementWhere(e, i) + " of " +
                    std::to_string(e.count) + " (the header promises " + std::to_string(e.count) +
                    ")");
  }
  [[noreturn]] void badToken(const PlyElement& e, uint64_t i, std::string_view tok) {
    fail(path_, "line " + std::to_string(f_.lineNumber()) + ": bad value " + shown(tok) +
                    " in " + elementWhere(e, i));
  }

  // ASCII: next token as a number (truncated file if none).
  double asciiNumber(const PlyElement& e, uint64_t i, TokenReader& tr) {
    std::string_view tok;
    double v;
    if (!tr.next(tok)) truncated(e, i);
    if (!parseDouble(tok, v)) badToken(e, i, tok);
    return v;
  }
  int64_t asciiInt(const PlyElement& e, uint64_t i, TokenReader& tr) {
    std::string_view tok;
    int64_t v;
    if (!tr.next(tok)) truncated(e, i);
    if (!parseInt(tok, v)) {
      double d;
      if (!parseDouble(tok, d) || d != std::floor(d) || std::abs(d) > 9.0e15) badToken(e, i, tok);
      v = static_cast<int64_t>(d);
    }
    return v;
  }

  void readVertices(const PlyElement& e) {
    const PlyVertexLayout l = plyVertexLayout(e);
    const bool colours = l.colours();
    checkVertexBytes(path_, e.count, colours, o_);
    va_.pos.resize(e.count);
    if (colours) va_.col.resize(e.count);
    stats_.vertices = e.count;
    stats_.hasColours = colours;
    stats_.vertexArrayBytes = e.count * (colours ? 16 : 12);
    std::vector<double> v(e.props.size(), 0.0);
    const bool fixed =
        std::none_of(e.props.begin(), e.props.end(), [](const PlyProp& p) { return p.list; });
    std::vector<size_t> offs(e.props.size());
    size_t record = 0;
    for (size_t k = 0; k < e.props.size(); ++k) {
      offs[k] = record;
      record += plySize(e.props[k].type);
    }
    MeshBounds& bounds = stats_.info.bounds;
    for (uint64_t i = 0; i < e.count; ++i) {
      if (ascii_) {
        for (size_t k = 0; k < e.props.size(); ++k) {
          if (e.props[k].list) {
            const int64_t n = asciiInt(e, i, tr_);
            for (int64_t j = 0; j < n; ++j) asciiNumber(e, i, tr_);
          } else {
            v[k] = asciiNumber(e, i, tr_);
          }
        }
      } else if (fixed) {
        if (!f_.ensure(record)) truncated(e, i);
        const uint8_t* p = f_.data();
        v[l.x] = plyScalar(p + offs[l.x], e.props[l.x].type, swap_);
        v[l.y] = plyScalar(p + offs[l.y], e.props[l.y].type, swap_);
        v[l.z] = plyScalar(p + offs[l.z], e.props[l.z].type, swap_);
        if (colours) {
          for (int k : {l.r, l.g, l.b, l.a})
            if (k >= 0) v[k] = plyScalar(p + offs[k], e.props[k].type, swap_);
        }
        f_.advance(record);
      } else {
        for (size_t k = 0; k < e.props.size(); ++k) {
          const PlyProp& p = e.props[k];
          if (p.list) {
            if (!f_.ensure(plySize(p.countType))) truncated(e, i);
            const int64_t n = plyInt(f_.data(), p.countType, swap_);
            f_.advance(plySize(p.countType));
            if (n < 0 || !f_.skip(static_cast<uint64_t>(n) * plySize(p.type))) truncated(e, i);
          } else {
            if (!f_.ensure(plySize(p.type))) truncated(e, i);
            v[k] = plyScalar(f_.data(), p.type, swap_);
            f_.advance(plySize(p.type));
          }
        }
      }
      const glm::vec3 pos(static_cast<float>(v[l.x]), static_cast<float>(v[l.y]),
                          static_cast<float>(v[l.z]));
      va_.pos[i] = pos;
      if (finite(pos)) bounds.extend(pos);
      else ++stats_.nonFiniteVertices;
      if (colours) va_.col[i] = plyColour(v.data(), e, l);
    }
    stats_.info.boundsKnown = true;
    emit_.setVertices(&va_);
  }

  uint32_t checkedIndex(int64_t idx, const PlyElement& e, uint64_t i) {
    if (idx < 0 || static_cast<uint64_t>(idx) >= va_.pos.size())
      fail(path_, elementWhere(e, i) + " (counting from 0): vertex index " + std::to_string(idx) +
                      " is out of range (" + std::to_string(va_.pos.size()) + " vertices)");
    return static_cast<uint32_t>(idx);
  }

  void pushIndex(int64_t idx, const PlyElement& e, uint64_t i) {
    if (e.kind == PlyElement::kFace) {
      fan_.push(checkedIndex(idx, e, i), emit_);
    } else if (idx == -1) {
      strip_.restart();
    } else if (strip_.push(checkedIndex(idx, e, i), emit_)) {
      ++stats_.strips;
    }
  }

  void endList(const PlyElement& e) {
    if (e.kind == PlyElement::kFace) {
      if (fan_.corners() < 3) ++stats_.shortFaces;
      else if (fan_.corners() > 3) ++stats_.polygonsFanned;
    }
  }

  void readFaces(const PlyElement& e) {
    for (uint64_t i = 0; i < e.count; ++i) {
      ++stats_.faces;
      for (size_t k = 0; k < e.props.size(); ++k) {
        const PlyProp& p = e.props[k];
        const bool isIndex = static_cast<int>(k) == e.indexProp;
        if (isIndex) {
          fan_.start();
          strip_.restart();
        }
        if (ascii_) {
          if (!p.list) {
            asciiNumber(e, i, tr_);
            continue;
          }
          const int64_t n = asciiInt(e, i, tr_);
          if (n < 0) fail(path_, elementWhere(e, i) + ": negative list length");
          for (int64_t j = 0; j < n; ++j) {
            if (isIndex) pushIndex(asciiInt(e, i, tr_), e, i);
            else asciiNumber(e, i, tr_);
          }
        } else {
          if (!p.list) {
            if (!f_.skip(plySize(p.type))) truncated(e, i);
            continue;
          }
          const size_t cs = plySize(p.countType), es = plySize(p.type);
          if (!f_.ensure(cs)) truncated(e, i);
          const int64_t n = plyInt(f_.data(), p.countType, swap_);
          f_.advance(cs);
          if (n < 0) fail(path_, elementWhere(e, i) + ": negative list length");
          const uint64_t bytes = static_cast<uint64_t>(n) * es;
          if (bytes > f_.remaining()) truncated(e, i);
          if (!isIndex) {
            f_.skip(bytes);
          } else if (bytes <= f_.capacity() / 2) {
            f_.ensure(static_cast<size_t>(bytes));
            const uint8_t* d = f_.data();
            for (int64_t j = 0; j < n; ++j) pushIndex(plyInt(d + j * es, p.type, swap_), e, i);
            f_.advance(static_cast<size_t>(bytes));
          } else {
            for (int64_t j = 0; j < n; ++j) {
              if (!f_.ensure(es)) truncated(e, i);
              pushIndex(plyInt(f_.data(), p.type, swap_), e, i);
              f_.advance(es);
            }
          }
        }
        if (isIndex) endList(e);
      }
    }
  }

  void skipElement(const PlyElement& e) {
    for (uint64_t i = 0; i < e.count; ++i) {
      for (const PlyProp& p : e.props) {
        if (ascii_) {
          if (p.list) {
            const int64_t n = asciiInt(e, i, tr_);
            for (int64_t j = 0; j < n; ++j) asciiNumber(e, i, tr_);
          } else {
            asciiNumber(e, i, tr_);
          }
        } else if (p.list) {
          if (!f_.ensure(plySize(p.countType))) truncated(e, i);
          const int64_t n = plyInt(f_.data(), p.countType, swap_);
          f_.advance(plySize(p.countType));
          if (n < 0 || !f_.skip(static_cast<uint64_t>(n) * plySize(p.type))) truncated(e, i);
        } else if (!f_.skip(plySize(p.type))) {
          truncated(e, i);
        }
      }
    }
    if (e.count > 0) warn(stats_, "PLY element '" + e.name + "' ignored");
  }

  void checkTrailing() {
    if (ascii_) {
      std::string_view tok;
      if (tr_.next(tok)) warn(stats_, "text after the last PLY element ignored");
    } else if (f_.remaining() > 0) {
      warn(stats_, std::to_string(f_.remaining()) + " bytes after the last PLY element ignored");
    }
  }

  FileBuffer& f_;
  fs::path path_;
  Emitter& emit_;
  VertexArray& va_;
  MeshReadStats& stats_;
  const MeshReadOptions& o_;
  PlyHeader h_;
  bool ascii_ = false, swap_ = false;
  TokenReader tr_;
  FanDecoder fan_;
  StripDecoder strip_;
};

// ---- OFF --------------------------------------------------------------------------------------

// Geomview OFF: "[ST][C][N]OFF", counts "nv nf [ne]", then vertex lines
// "x y z [nx ny nz] [r g b [a]] [s t]" and face lines "n i0 .. i(n-1) [colour]". '#' comments.
class OffReader {
 public:
  OffReader(FileBuffer& f, Emitter& emit, VertexArray& va, MeshReadStats& stats,
            const MeshReadOptions& o)
      : f_(f), path_(f.path()), emit_(emit), va_(va), stats_(stats), o_(o) {}

  void run(bool verticesOnly) {
    std::string_view line;
    if (!dataLine(line)) fail(path_, "empty OFF file");
    Tokens t{line};
    std::string_view kw;
    t.next(kw);
    if (kw.size() < 3 || kw.substr(kw.size() - 3) != "OFF")
      fail(path_, "not an OFF file (it does not start with 'OFF')");
    for (char c : kw.substr(0, kw.size() - 3)) {
      if (c == 'C') colours_ = true;
      else if (c == 'N') normals_ = true;
      else if (c != 'S' && c != 'T')
        fail(path_, "unsupported OFF variant " + shown(kw) + " (4D and nD OFF)");
    }
    std::string_view tok;
    int64_t counts[3] = {-1, -1, 0};
    int got = 0;
    if (t.next(tok)) {
      if (tok == "BINARY") fail(path_, "binary OFF is not supported");
      if (!parseInt(tok, counts[got++])) fail(path_, "bad OFF counts " + shown(tok));
    }
    while (got < 2) {
      if (got == 0 && !dataLine(line)) fail(path_, "truncated: no vertex and face counts");
      if (got == 0) t = Tokens{line};
      while (got < 3 && t.next(tok))
        if (!parseInt(tok, counts[got++])) fail(path_, "bad OFF counts " + shown(tok));
      if (got < 2) fail(path_, "line " + std::to_string(f_.lineNumber()) +
                                   ": want 'vertices faces [edges]' counts");
    }
    if (counts[0] < 0 || counts[1] < 0) fail(path_, "negative OFF counts");
    const uint64_t nv = static_cast<uint64_t>(counts[0]), nf = static_cast<uint64_t>(counts[1]);
    // Each vertex line needs at least "0 0 0\n", each face line "0\n".
    const uint64_t body = f_.remaining();
    if (nv > (body + 1) / 6 || nf > (body + 1 - nv * 6) / 2 + 1)
      fail(path_, "the header declares " + std::to_string(nv) + " vertices and " +
                      std::to_string(nf) + " faces but only " + std::to_string(body) +
                      " bytes follow (truncated or corrupt file)");
    MeshInfo& info = stats_.info;
    info.format = MeshFormat::kOff;
    info.formatName = "OFF";
    info.vertices = nv;
    info.faces = nf;
    info.triangleEstimate = nf;
    info.hasColours = colours_;

    checkVertexBytes(path_, nv, colours_, o_);
    va_.pos.resize(nv);
    if (colours_) va_.col.resize(nv);
    stats_.vertices = nv;
    stats_.hasColours = colours_;
    stats_.vertexArrayBytes = nv * (colours_ ? 16 : 12);
    for (uint64_t i = 0; i < nv; ++i) {
      if (!dataLine(line))
        fail(path_, "truncated: the file ends after " + std::to_string(i) + " of " +
                        std::to_string(nv) + " vertices");
      readVertex(line, i);
    }
    info.boundsKnown = true;
    emit_.setVertices(&va_);
    if (verticesOnly) return;
    emit_.begin(info);
    FanDecoder fan;
    for (uint64_t i = 0; i < nf; ++i) {
      if (!dataLine(line))
        fail(path_, "truncated: the file ends after " + std::to_string(i) + " of " +
                        std::to_string(nf) + " faces");
      ++stats_.faces;
      Tokens ft{line};
      int64_t n = -1;
      if (!ft.next(tok) || !parseInt(tok, n) || n < 0)
        fail(path_, "line " + std::to_string(f_.lineNumber()) + ": face " + std::to_string(i) +
                        " (counting from 0) has a bad corner count");
      fan.start();
      for (int64_t j = 0; j < n; ++j) {
        int64_t idx;
        if (!ft.next(tok) || !parseInt(tok, idx))
          fail(path_, "line " + std::to_string(f_.lineNumber()) + ": face " + std::to_string(i) +
                          " (counting from 0) declares " + std::to_string(n) +
                          " corners but does not list them" + cutShort(f_));
        if (idx < 0 || static_cast<uint64_t>(idx) >= nv)
          fail(path_, "line " + std::to_string(f_.lineNumber()) + ": face " + std::to_string(i) +
                          " (counting from 0): vertex index " + std::to_string(idx) +
                          " is out of range (" + std::to_string(nv) + " vertices)");
        fan.push(static_cast<uint32_t>(idx), emit_);
      }
      if (n < 3) ++stats_.shortFaces;
      else if (n > 3) ++stats_.polygonsFanned;
    }
    if (dataLine(line)) warn(stats_, "text after the last OFF face ignored");
  }

 private:
  // Next line with data, comments removed.
  bool dataLine(std::string_view& line) {
    while (f_.nextLine(line)) {
      const size_t hash = line.find('#');
      if (hash != std::string_view::npos) line = line.substr(0, hash);
      Tokens t{line};
      std::string_view tok;
      if (t.next(tok)) return true;
    }
    return false;
  }

  void readVertex(std::string_view line, uint64_t i) {
    Tokens t{line};
    std::string_view tok;
    double v[3];
    for (double& c : v) {
      if (!t.next(tok) || !parseDouble(tok, c))
        fail(path_, "line " + std::to_string(f_.lineNumber()) + ": vertex " + std::to_string(i) +
                        " needs 3 coordinates" + cutShort(f_));
    }
    const glm::vec3 p(static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2]));
    va_.pos[i] = p;
    if (finite(p)) stats_.info.bounds.extend(p);
    else ++stats_.nonFiniteVertices;
    if (!colours_) return;
    if (normals_)
      for (int k = 0; k < 3; ++k) t.next(tok);
    double c[4] = {1, 1, 1, 1};
    bool isFloat = false;
    int n = 0;
    while (n < 4 && t.next(tok)) {
      if (!parseDouble(tok, c[n])) break;
      if (tok.find_first_of(".eE") != std::string_view::npos) isFloat = true;
      ++n;
    }
    if (n < 3) {
      va_.col[i] = kWhite;
    } else if (isFloat) {
      va_.col[i] = colourFromFloat(c[0], c[1], c[2], n == 4 ? c[3] : 1.0);
    } else {
      va_.col[i] = colourFromInt(c[0], c[1], c[2], n == 4 ? c[3] : 255.0);
    }
  }

  FileBuffer& f_;
  fs::path path_;
  Emitter& emit_;
  VertexArray& va_;
  MeshReadStats& stats_;
  const MeshReadOptions& o_;
  bool colours_ = false, normals_ = false;
};

// ---- OBJ --------------------------------------------------------------------------------------

// "v x y z [w | r g b]" and "f a b c ..." with a = "i", "i/t", "i/t/n" or "i//n"; negative
// indices count back from the last vertex so far. Other statements are ignored.
// note: a face may only use vertices defined before it (true of every common exporter).
class ObjReader {
 public:
  ObjReader(FileBuffer& f, Emitter& emit, VertexArray& va, MeshReadStats& stats,
            const MeshReadOptions& o)
      : f_(f), path_(f.path()), emit_(emit), va_(va), stats_(stats), o_(o) {}

  void run() {
    MeshInfo& info = stats_.info;
    info.format = MeshFormat::kObj;
    info.formatName = "OBJ";
    info.triangleEstimate = f_.size() / 48;  // typical bytes per triangle (v and f lines)
    emit_.setVertices(&va_);
    emit_.begin(info);
    std::string_view line, tok;
    FanDecoder fan;
    const uint64_t bytesPerVertex = 16;
    while (f_.nextLine(line)) {
      size_t b = 0;
      while (b < line.size() && isSpace(line[b])) ++b;
      if (b + 1 >= line.size() || !isSpace(line[b + 1])) continue;
      const char kind = line[b];
      if (kind != 'v' && kind != 'f') continue;
      Tokens t{line.substr(b + 2)};
      if (kind == 'v') {
        double c[7];
        int n = 0;
        while (n < 7 && t.next(tok)) {
          if (tok[0] == '#') break;
          if (!parseDouble(tok, c[n]))
            fail(path_, "line " + std::to_string(f_.lineNumber()) + ": bad number " + shown(tok) +
                            cutShort(f_));
          ++n;
        }
        if (n < 3)
          fail(path_, "line " + std::to_string(f_.lineNumber()) + ": vertex needs 3 coordinates" +
                          cutShort(f_));
        if (va_.pos.size() >= kMaxVertices ||
            (o_.maxVertexBytes != 0 && (va_.pos.size() + 1) * bytesPerVertex > o_.maxVertexBytes))
          checkVertexBytes(path_, va_.pos.size() + 1, true, o_,
                           "line " + std::to_string(f_.lineNumber()) + ": ");
        const glm::vec3 p(static_cast<float>(c[0]), static_cast<float>(c[1]),
                          static_cast<float>(c[2]));
        if (finite(p)) info.bounds.extend(p);
        else ++stats_.nonFiniteVertices;
        if (n >= 6) {
          if (va_.col.size() < va_.pos.size()) va_.col.resize(va_.pos.size(), kWhite);
          va_.col.push_back(colourFromFloat(c[3], c[4], c[5], 1.0));
          stats_.hasColours = true;
        } else if (!va_.col.empty()) {
          va_.col.push_back(kWhite);
        }
        va_.pos.push_back(p);
        continue;
      }
      // A face.
      const uint64_t face = stats_.faces++;
      fan.start();
      while (t.next(tok)) {
        if (tok[0] == '#') break;
        const char* e = tok.data() + tok.size();
        int64_t idx = 0;
        auto [ptr, ec] = std::from_chars(tok.data(), e, idx);
        if (ec != std::errc() || (ptr != e && *ptr != '/'))
          fail(path_, "line " + std::to_string(f_.lineNumber()) + ": bad face corner " +
                          shown(tok) + cutShort(f_));
        const int64_t n = static_cast<int64_t>(va_.pos.size());
        const int64_t i = idx > 0 ? idx - 1 : n + idx;
        if (idx == 0 || i < 0 || i >= n)
          fail(path_, "line " + std::to_string(f_.lineNumber()) + ": face " +
                          std::to_string(face) + " (counting from 0): vertex index " +
                          std::to_string(idx) + " is out of range (" + std::to_string(n) +
                          " vertices defined before it)");
        fan.push(static_cast<uint32_t>(i), emit_);
      }
      if (fan.corners() < 3) ++stats_.shortFaces;
      else if (fan.corners() > 3) ++stats_.polygonsFanned;
    }
    if (!va_.col.empty()) va_.col.resize(va_.pos.size(), kWhite);
    stats_.vertices = va_.pos.size();
    stats_.vertexArrayBytes = va_.pos.size() * (va_.col.empty() ? 12 : 16);
    info.vertices = va_.pos.size();
    info.faces = stats_.faces;
    info.hasColours = stats_.hasColours;
  }

 private:
  FileBuffer& f_;
  fs::path path_;
  Emitter& emit_;
  VertexArray& va_;
  MeshReadStats& stats_;
  const MeshReadOptions& o_;
};

// ---- STL --------------------------------------------------------------------------------------

bool startsWith(std::string_view s, std::string_view p) { return s.substr(0, p.size()) == p; }

// Binary if the size matches 84 + 50 n exactly (many binary files also start with "solid"),
// unless the text after "solid" looks like an ASCII STL.
bool stlIsBinary(FileBuffer& f) {
  f.ensure(std::min<uint64_t>(f.size(), 512));
  const size_t n = f.available();
  const char* d = reinterpret_cast<const char*>(f.data());
  const std::string_view head(d, n);
  const bool solid = startsWith(head, "solid");
  if (n >= 84) {
    uint32_t count;
    std::memcpy(&count, d + 80, 4);
    if (std::endian::native == std::endian::big) count = __builtin_bswap32(count);
    if (f.size() == 84 + 50 * uint64_t{count}) {
      if (!solid) return true;
      const size_t nl = head.find('\n');
      if (nl == std::string_view::npos) return true;
      size_t b = nl + 1;
      while (b < n && (isSpace(head[b]) || head[b] == '\n')) ++b;
      const std::string_view rest = head.substr(b);
      return !(startsWith(rest, "facet") || startsWith(rest, "endsolid"));
    }
  }
  return !solid;
}

class StlReader {
 public:
  StlReader(FileBuffer& f, Emitter& emit, MeshReadStats& stats)
      : f_(f), path_(f.path()), emit_(emit), stats_(stats) {}

  void run() {
    MeshInfo& info = stats_.info;
    info.format = MeshFormat::kStl;
    if (stlIsBinary(f_)) runBinary();
    else runAscii();
  }

 private:
  void runBinary() {
    MeshInfo& info = stats_.info;
    info.formatName = "STL binary";
    if (!f_.ensure(84)) fail(path_, "truncated binary STL: shorter than its 84-byte header");
    uint32_t count;
    std::memcpy(&count, f_.data() + 80, 4);
    if (std::endian::native == std::endian::big) count = __builtin_bswap32(count);
    f_.advance(84);
    const uint64_t need = 84 + 50 * uint64_t{count};
    if (f_.size() < need)
      fail(path_, "truncated binary STL: the header promises " + std::to_string(count) +
                      " facets (" + std::to_string(need) + " bytes) but the file has " +
                      std::to_string(f_.size()) + " bytes");
    if (f_.size() > need)
      warn(stats_, std::to_string(f_.size() - need) + " bytes after the last STL facet ignored");
    info.faces = count;
    info.triangleEstimate = count;
    emit_.begin(info);
    for (uint32_t i = 0; i < count; ++i) {
      if (!f_.ensure(50)) fail(path_, "truncated binary STL in facet " + std::to_string(i));
      const uint8_t* d = f_.data() + 12;  // skip the normal
      constexpr bool kSwap = std::endian::native == std::endian::big;
      glm::vec3 p[3];
      for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c)
          p[k][c] = std::bit_cast<float>(loadSwapped<uint32_t>(d + 12 * k + 4 * c, kSwap));
      f_.advance(50);
      ++stats_.faces;
      emit_.soup(p[0], p[1], p[2]);
    }
  }

  void runAscii() {
    MeshInfo& info = stats_.info;
    info.formatName = "STL ASCII";
    emit_.begin(info);
    std::string_view line, tok;
    glm::vec3 p[3];
    int corners = 0;
    bool inFacet = false, sawSolid = false;
    while (f_.nextLine(line)) {
      Tokens t{line};
      if (!t.next(tok)) continue;
      const std::string where = "line " + std::to_string(f_.lineNumber());
      // A bad last line without its line break: the file was cut in the middle of it.
      const auto bad = [&](const std::string& what) {
        if (f_.lineUnterminated())
          fail(path_, "truncated ASCII STL: the file ends in the middle of " + where + " (" +
                          what + ")");
        fail(path_, where + ": " + what);
      };
      if (tok == "vertex") {
        if (!inFacet) fail(path_, where + ": vertex outside a facet");
        double c[3];
        for (double& v : c)
          if (!t.next(tok) || !parseDouble(tok, v)) bad("vertex needs 3 coordinates");
        if (corners < 3)
          p[corners] = glm::vec3(static_cast<float>(c[0]), static_cast<float>(c[1]),
                                 static_cast<float>(c[2]));
        ++corners;
      } else if (tok == "facet") {
        if (inFacet) fail(path_, where + ": 'facet' inside a facet (missing 'endfacet')");
        inFacet = true;
        corners = 0;
      } else if (tok == "endfacet") {
        if (!inFacet) fail(path_, where + ": 'endfacet' without 'facet'");
        if (corners != 3)
          fail(path_, where + ": facet " + std::to_string(stats_.faces) + " has " +
                          std::to_string(corners) + " vertices (STL facets are triangles)");
        inFacet = false;
        ++stats_.faces;
        emit_.soup(p[0], p[1], p[2]);
      } else if (tok == "solid") {
        sawSolid = true;
      } else if (tok == "outer" || tok == "endloop" || tok == "endsolid") {
      } else {
        bad("unexpected " + shown(tok) + " in an ASCII STL");
      }
    }
    if (!sawSolid) fail(path_, "not an ASCII STL (no 'solid')");
    if (inFacet) fail(path_, "truncated ASCII STL: the file ends inside a facet");
    info.faces = stats_.faces;
  }

  FileBuffer& f_;
  fs::path path_;
  Emitter& emit_;
  MeshReadStats& stats_;
};

// ---- detection and the entry points ------------------------------------------------------------

bool looksLikeOff(std::string_view head) {
  size_t b = 0;
  for (;;) {
    while (b < head.size() && (isSpace(head[b]) || head[b] == '\n')) ++b;
    if (b < head.size() && head[b] == '#') {
      const size_t nl = head.find('\n', b);
      if (nl == std::string_view::npos) return false;
      b = nl + 1;
      continue;
    }
    break;
  }
  size_t e = b;
  while (e < head.size() && (std::isalnum(static_cast<unsigned char>(head[e])))) ++e;
  const std::string_view kw = head.substr(b, e - b);
  return kw.size() >= 3 && kw.size() <= 8 && kw.substr(kw.size() - 3) == "OFF" &&
         kw.find_first_not_of("STCN4nOF") == std::string_view::npos;
}

MeshFormat detectFormat(FileBuffer& f) {
  const fs::path& path = f.path();
  if (f.size() == 0) fail(path, "empty file");
  f.ensure(std::min<uint64_t>(f.size(), 512));
  const std::string_view head(reinterpret_cast<const char*>(f.data()), f.available());
  const std::string ext = lower(path.extension().string());
  const bool plyMagic = head.size() >= 4 && startsWith(head, "ply") &&
                        (head[3] == '\n' || head[3] == '\r');
  if (ext == ".ply") {
    if (!plyMagic) fail(path, "not a PLY file (it does not start with 'ply')");
    return MeshFormat::kPly;
  }
  if (ext == ".off") {
    if (!looksLikeOff(head)) fail(path, "not an OFF file (it does not start with 'OFF')");
    return MeshFormat::kOff;
  }
  if (ext == ".obj") return MeshFormat::kObj;
  if (ext == ".stl") return MeshFormat::kStl;
  if (plyMagic) return MeshFormat::kPly;
  if (looksLikeOff(head)) return MeshFormat::kOff;
  if (startsWith(head, "solid")) return MeshFormat::kStl;
  fail(path, "unsupported mesh format (expected .ply, .obj, .off or .stl)");
}

const char* genericName(MeshFormat f) {
  switch (f) {
    case MeshFormat::kPly: return "PLY";
    case MeshFormat::kObj: return "OBJ";
    case MeshFormat::kOff: return "OFF";
    case MeshFormat::kStl: return "STL";
  }
  return "?";
}

void checkOptions(const fs::path& path, const MeshReadOptions& o) {
  if (o.chunkTriangles == 0) fail(path, "bad read options: chunkTriangles must be at least 1");
}

class NullSink : public TriangleSink {
 public:
  void consume(const MeshTriangle*, size_t) override {}
};

// The one reader behind the entry points. va receives the vertex array of indexed formats.
MeshReadStats streamImpl(const fs::path& path, TriangleSink& sink, const MeshReadOptions& o,
                         VertexArray& va, bool verticesOnly) {
  const auto t0 = std::chrono::steady_clock::now();
  checkOptions(path, o);
  FileBuffer f(path);
  MeshReadStats stats;
  stats.info.format = detectFormat(f);
  stats.info.formatName = genericName(stats.info.format);
  Emitter emit(sink, o, stats);
  switch (stats.info.format) {
    case MeshFormat::kPly: PlyReader(f, emit, va, stats, o).run(verticesOnly); break;
    case MeshFormat::kOff: OffReader(f, emit, va, stats, o).run(verticesOnly); break;
    case MeshFormat::kObj: ObjReader(f, emit, va, stats, o).run(); break;
    case MeshFormat::kStl: StlReader(f, emit, stats).run(); break;
  }
  if (!verticesOnly) {
    if (stats.faces == 0)
      fail(path, "no faces (" + stats.info.formatName + " with " + std::to_string(stats.vertices) +
                     " vertices and no triangles: a point cloud, not a mesh)");
    emit.begin(stats.info);
    emit.finish();
    if (stats.trianglesOut == 0) {
      // Every triangle was repaired away (e.g. all vertices at one point): nothing to build from.
      std::string why = "no valid triangles: ";
      if (stats.trianglesRead == 0) {
        why += "all " + std::to_string(stats.faces) + " faces have fewer than 3 corners";
      } else {
        why += "all " + std::to_string(stats.trianglesRead) + " triangles were dropped (" +
               std::to_string(stats.droppedNonFinite) + " with a NaN or infinite coordinate, " +
               std::to_string(stats.droppedDegenerate) + " degenerate: repeated vertex or zero " +
               "area, " + std::to_string(stats.droppedDuplicate) + " duplicate)";
      }
      fail(path, why);
    }
  }
  stats.bytesRead = f.offset();
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return stats;
}

}  // namespace

MeshInfo detectMesh(const fs::path& path) {
  FileBuffer f(path, 4096);
  MeshInfo info;
  info.format = detectFormat(f);
  info.formatName = genericName(info.format);
  return info;
}

MeshInfo probeMesh(const fs::path& path, const MeshReadOptions& options) {
  const MeshInfo kind = detectMesh(path);
  VertexArray va;
  NullSink sink;
  if (kind.format == MeshFormat::kPly || kind.format == MeshFormat::kOff)
    return streamImpl(path, sink, options, va, true).info;
  MeshReadOptions o = options;
  o.removeDuplicates = false;
  const MeshReadStats s = streamImpl(path, sink, o, va, false);
  MeshInfo info = s.info;
  info.bounds = s.bounds;  // of the valid triangles
  info.boundsKnown = true;
  info.triangleEstimate = s.trianglesOut;
  return info;
}

MeshReadStats streamMesh(const fs::path& path, TriangleSink& sink, const MeshReadOptions& options) {
  VertexArray va;
  return streamImpl(path, sink, options, va, false);
}

MeshReadStats streamMesh(const fs::path& path,
                         const std::function<void(std::span<const MeshTriangle>)>& consume,
                         const MeshReadOptions& options) {
  class FunctionSink : public TriangleSink {
   public:
    explicit FunctionSink(const std::function<void(std::span<const MeshTriangle>)>& f) : f_(f) {}
    void consume(const MeshTriangle* t, size_t n) override { f_(std::span(t, n)); }

   private:
    const std::function<void(std::span<const MeshTriangle>)>& f_;
  } sink(consume);
  return streamMesh(path, sink, options);
}

IndexedMesh readMesh(const fs::path& path, const MeshReadOptions& options) {
  IndexedMesh mesh;
  VertexArray va;
  struct Weld {
    size_t operator()(const glm::vec3& p) const {
      return mix64((uint64_t{std::bit_cast<uint32_t>(p.x)} << 32 | std::bit_cast<uint32_t>(p.y)) ^
                   mix64(std::bit_cast<uint32_t>(p.z)));
    }
  };
  std::unordered_map<glm::vec3, uint32_t, Weld> welded;
  class Collect : public TriangleSink {
   public:
    Collect(IndexedMesh& m, std::unordered_map<glm::vec3, uint32_t, Weld>& w) : m_(m), w_(w) {}
    void consume(const MeshTriangle* t, size_t n) override {
      for (size_t i = 0; i < n; ++i) {
        std::array<uint32_t, 3> tri = t[i].v;
        if (tri[0] == kNoVertex) {
          for (int k = 0; k < 3; ++k) {
            auto [it, added] = w_.try_emplace(t[i].p[k] + 0.0f, static_cast<uint32_t>(w_.size()));
            if (added) m_.positions.push_back(t[i].p[k]);
            tri[k] = it->second;
          }
        }
        m_.triangles.push_back(tri);
      }
    }

   private:
    IndexedMesh& m_;
    std::unordered_map<glm::vec3, uint32_t, Weld>& w_;
  } sink(mesh, welded);
  mesh.stats = streamImpl(path, sink, options, va, false);
  if (mesh.stats.info.format != MeshFormat::kStl) {
    mesh.positions = std::move(va.pos);
    mesh.colours = std::move(va.col);
  }
  return mesh;
}

}  // namespace gimlod
