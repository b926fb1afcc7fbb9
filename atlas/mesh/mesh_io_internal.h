// Shared parts of the mesh readers (atlas/mesh/mesh_io_*.cpp): buffered file input, tokens and
// number parsing, the vertex array, and the emitter that repairs, counts and delivers triangles.
// Internal to atlas/mesh; not part of the public interface (atlas/mesh/mesh_io.h).
#pragma once

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <glm/common.hpp>

#include "atlas/mesh/mesh_io.h"

namespace gimlod::meshio {

namespace fs = std::filesystem;

inline constexpr size_t kBufferBytes = size_t{1} << 20;
inline constexpr uint64_t kMaxVertices = uint64_t{kNoVertex} - 1;
inline constexpr size_t kMaxWarnings = 16;
inline const glm::u8vec4 kWhite{255, 255, 255, 255};

[[noreturn]] inline void fail(const fs::path& file, const std::string& what) {
  throw InputError(file.string() + ": " + what);
}

inline void warn(MeshReadStats& stats, std::string what) {
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
    // No larger than the file needs: a small file costs no megabyte buffer.
    capacity_ = static_cast<size_t>(std::max<uint64_t>(std::min<uint64_t>(capacity, size_ + 1), 4096));
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
        fail(path_, "line " + std::to_string(line_ + 1) + " is longer than " + std::to_string(capacity_ >> 20) +
                        " MiB (binary data in a text file?)");
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
inline std::string cutShort(const FileBuffer& f) {
  return f.lineUnterminated() ? " (truncated: the file ends in the middle of this line)" : "";
}

inline bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

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
inline bool parseDouble(std::string_view tok, double& v) {
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

inline bool parseInt(std::string_view tok, int64_t& v) {
  const char* b = tok.data();
  const char* e = b + tok.size();
  if (b != e && *b == '+') ++b;
  auto [ptr, ec] = std::from_chars(b, e, v);
  return ec == std::errc() && ptr == e;
}

inline std::string shown(std::string_view tok) {
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

inline bool finite(const glm::vec3& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); }

// Exactly zero area: the cross product of two edges (computed in double) vanishes.
inline bool zeroArea(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
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

inline uint64_t mix64(uint64_t x) {
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
      : sink_(sink),
        stats_(stats),
        dedupe_(o.removeDuplicates),
        dup_(o.duplicateSetBytes),
        chunkSize_(o.chunkTriangles) {}
  void setVertices(const VertexArray* va) { va_ = va; }
  void begin(const MeshInfo& info) {
    if (begun_) return;
    begun_ = true;
    if (dedupe_) dup_.reserve(info.triangleEstimate);
    chunk_.reserve(std::min<size_t>(std::min<uint64_t>(chunkSize_, info.triangleEstimate + 1), size_t{1} << 20) +
                   kBatch);
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
    if (va_->col.empty())
      t.c = {kWhite, kWhite, kWhite};
    else
      t.c = {va_->col[a], va_->col[b], va_->col[c]};
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
    DupKey k{mix64(w[0] ^ mix64(w[1] ^ mix64(w[2]))), mix64(w[2] + 0x632be59bd9b4e019ull) ^ mix64(w[0] + 3 * w[1])};
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
      warn(stats_,
           "the duplicate-triangle set reached its memory bound; later duplicates are "
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
    if (n_ == 0)
      first_ = i;
    else if (n_ >= 2)
      e.indexed(first_, prev_, i, false);
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
      if ((n_ - 2) % 2 == 0)
        e.indexed(a_, b_, i, true);
      else
        e.indexed(b_, a_, i, true);
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

inline void checkVertexBytes(const fs::path& path, uint64_t vertices, bool colours, const MeshReadOptions& o,
                             const std::string& where = "") {
  if (vertices > kMaxVertices)
    fail(path, std::to_string(vertices) + " vertices: more than the supported " + std::to_string(kMaxVertices));
  const uint64_t bytes = vertices * (colours ? 16 : 12);
  if (o.maxVertexBytes != 0 && bytes > o.maxVertexBytes)
    fail(path, where + "the vertex array of " + std::to_string(vertices) + " vertices needs " + std::to_string(bytes) +
                   " bytes, more than the " + std::to_string(o.maxVertexBytes) +
                   " bytes allowed (raise the memory cap, or convert the mesh to binary STL, which "
                   "streams without a vertex array)");
}

inline glm::u8vec4 colourFromFloat(double r, double g, double b, double a) {
  auto c = [](double v) {
    if (!(v > 0)) return uint8_t{0};
    return v >= 1 ? uint8_t{255} : static_cast<uint8_t>(std::lround(v * 255.0));
  };
  return {c(r), c(g), c(b), c(a)};
}

inline glm::u8vec4 colourFromInt(double r, double g, double b, double a) {
  auto c = [](double v) {
    if (!(v > 0)) return uint8_t{0};
    return v >= 255 ? uint8_t{255} : static_cast<uint8_t>(std::lround(v));
  };
  return {c(r), c(g), c(b), c(a)};
}

// A value of type U at p, its bytes reversed if swap (binary PLY and STL).
template <typename U>
U loadSwapped(const uint8_t* p, bool swap) {
  U u;
  std::memcpy(&u, p, sizeof u);
  if (swap) {
    if constexpr (sizeof(U) == 2)
      u = __builtin_bswap16(u);
    else if constexpr (sizeof(U) == 4)
      u = __builtin_bswap32(u);
    else
      u = __builtin_bswap64(u);
  }
  return u;
}

inline bool startsWith(std::string_view s, std::string_view p) { return s.substr(0, p.size()) == p; }

// What a reader of an indexed format (PLY, OFF, OBJ) works with: the file, where its triangles
// go, its vertex array, the counts and the options.
class IndexedReader {
 public:
  IndexedReader(FileBuffer& f, Emitter& emit, VertexArray& va, MeshReadStats& stats, const MeshReadOptions& o)
      : f_(f), path_(f.path()), emit_(emit), va_(va), stats_(stats), o_(o) {}

 protected:
  FileBuffer& f_;
  fs::path path_;
  Emitter& emit_;
  VertexArray& va_;
  MeshReadStats& stats_;
  const MeshReadOptions& o_;
};

// The format readers, one per file (atlas/mesh/mesh_io_ply.cpp and so on). Each reads the file
// from its start; the indexed formats fill va, and with verticesOnly stop after the vertices.
void readPly(FileBuffer& f, Emitter& emit, VertexArray& va, MeshReadStats& stats, const MeshReadOptions& o,
             bool verticesOnly);
void readOff(FileBuffer& f, Emitter& emit, VertexArray& va, MeshReadStats& stats, const MeshReadOptions& o,
             bool verticesOnly);
void readObj(FileBuffer& f, Emitter& emit, VertexArray& va, MeshReadStats& stats, const MeshReadOptions& o);
void readStl(FileBuffer& f, Emitter& emit, MeshReadStats& stats);

}  // namespace gimlod::meshio
