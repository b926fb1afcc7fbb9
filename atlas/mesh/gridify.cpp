// Gridify: the first out-of-core stage of the mesh atlas. Triangles are bucketed by centroid into
// a uniform grid; per-cell buffers are appended to cell files whenever their total would pass a
// share of the memory cap, so memory is bounded whatever the mesh size.
// Based on: the out-of-core clustering front end of Niski, Purnomo, Cohen, "Multi-grained Level
// of Detail Using a Hierarchical Seamless Texture Atlas", I3D 2007, section 5 (and Lindstrom,
// "Out-of-core simplification of large polygonal models", SIGGRAPH 2000, for the streamed
// uniform-grid bucketing).
#include "atlas/mesh/gridify.h"
#include "atlas/mesh/portable_math.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <random>

#include <fcntl.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "core/stage_meter.h"

namespace gimlod {

namespace fs = std::filesystem;

static_assert(sizeof(std::array<glm::vec3, 3>) == 36 && sizeof(std::array<glm::u8vec4, 3>) == 12,
              "triangle records are copied as packed floats and bytes");
static_assert(std::endian::native == std::endian::little,
              "cell files are written in native order, which must be little-endian");

namespace {

constexpr char kCellMagic[4] = {'G', 'L', 'G', 'C'};
constexpr uint32_t kCellHeaderBytes = 16;
constexpr uint64_t kMinMemoryBytes = uint64_t{64} << 20;
constexpr uint64_t kMinBufferBytes = uint64_t{64} << 10;
constexpr uint32_t kMaxCellsPerAxis = 1024;
constexpr const char* kGridFormatTag = "gimlod-grid";

[[noreturn]] void fail(const fs::path& file, const std::string& what) { throw InputError(file.string() + ": " + what); }

std::string cellFileName(uint32_t id) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "cells/cell_%08u.bin", id);
  return buf;
}

void writeAll(int fd, const void* data, size_t bytes, const fs::path& file) {
  const auto* p = static_cast<const uint8_t*>(data);
  while (bytes > 0) {
    const ssize_t w = ::write(fd, p, std::min<size_t>(bytes, size_t{1} << 30));
    if (w < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(fd);
      fail(file, std::string("write failed: ") + std::strerror(err));
    }
    p += w;
    bytes -= static_cast<size_t>(w);
  }
}

void validate(const GridifyOptions& o) {
  auto bad = [](const std::string& what) { throw InputError("bad gridify options: " + what); };
  if (o.maxMemoryBytes < kMinMemoryBytes)
    bad("maxMemoryBytes " + std::to_string(o.maxMemoryBytes) + " is below the minimum of 64 MiB");
  if (o.targetTrianglesPerCell == 0) bad("targetTrianglesPerCell must be at least 1");
  if (!(o.bufferFraction > 0.0 && o.bufferFraction <= 0.5)) bad("bufferFraction must be in (0, 0.5]");
  if (static_cast<double>(o.maxMemoryBytes) * o.bufferFraction < double(kMinBufferBytes))
    bad("bufferFraction * maxMemoryBytes is below 64 KiB");
  if (o.read.chunkTriangles == 0) bad("read.chunkTriangles must be at least 1");
  if (uint64_t{o.read.chunkTriangles} * sizeof(MeshTriangle) > o.maxMemoryBytes / 16)
    bad("read.chunkTriangles is too large for the memory cap (a chunk may use 1/16 of it)");
}

// Buckets triangles into per-cell buffers and appends them to cell files under a byte budget.
class GridWriter : public TriangleSink {
 public:
  GridWriter(const fs::path& dir, const GridifyOptions& o, const MeshInfo* probed, GridifyResult& result)
      : dir_(dir), o_(o), probed_(probed), r_(result) {
    budget_ = static_cast<uint64_t>(static_cast<double>(o.maxMemoryBytes) * o.bufferFraction);
    r_.bufferBudgetBytes = budget_;
  }

  void begin(const MeshInfo& info) override {
    const MeshInfo& src = info.boundsKnown ? info : *probed_;
    GridManifest& m = r_.manifest;
    m.hasColours = info.hasColours || (probed_ && probed_->hasColours);
    m.recordBytes = m.hasColours ? 48 : 36;
    const uint64_t maxCells = std::min<uint64_t>(1u << 20, o_.maxMemoryBytes / 16 / sizeof(Cell));
    m.dims =
        chooseGridDims(src.bounds, std::max<uint64_t>(src.triangleEstimate, 1), o_.targetTrianglesPerCell, maxCells);
    for (int a = 0; a < 3; ++a) {
      const double lo = src.bounds.empty() ? 0.0 : double(src.bounds.min[a]);
      const double hi = src.bounds.empty() ? 1.0 : double(src.bounds.max[a]);
      m.origin[a] = lo;
      m.cellSize[a] = hi > lo ? (hi - lo) / m.dims[a] : 1.0;
    }
    cells_.resize(size_t{m.dims[0]} * m.dims[1] * m.dims[2]);
    std::error_code ec;
    fs::create_directory(dir_ / "cells", ec);
    if (ec) fail(dir_ / "cells", "cannot create directory: " + ec.message());
  }

  void consume(const MeshTriangle* tris, size_t n) override {
    const GridManifest& m = r_.manifest;
    const size_t rec = m.recordBytes;
    uint8_t record[48];
    for (size_t i = 0; i < n; ++i) {
      const MeshTriangle& t = tris[i];
      const uint32_t id = m.cellId(m.cellOf(t));
      std::memcpy(record, t.p.data(), 36);
      if (m.hasColours) std::memcpy(record + 36, t.c.data(), 12);
      Cell& c = cells_[id];
      if (c.buf.size() + rec > c.buf.capacity()) grow(id, rec);
      c.buf.insert(c.buf.end(), record, record + rec);
      ++c.triangles;
      ++r_.triangles;
      r_.manifest.bounds.extend(t.p[0]);
      r_.manifest.bounds.extend(t.p[1]);
      r_.manifest.bounds.extend(t.p[2]);
    }
  }

  uint64_t cellTableBytes() const { return cells_.size() * sizeof(Cell); }

  // Writes every buffer out and renames the cell files to their final names.
  void finish() {
    for (uint32_t id = 0; id < cells_.size(); ++id)
      if (!cells_[id].buf.empty()) flushCell(id);
    GridManifest& m = r_.manifest;
    for (uint32_t id = 0; id < cells_.size(); ++id) {
      Cell& c = cells_[id];
      if (c.triangles == 0) continue;
      GridCell g;
      g.id = id;
      g.coord = {id % m.dims[0], (id / m.dims[0]) % m.dims[1], id / (m.dims[0] * m.dims[1])};
      g.triangles = c.triangles;
      g.file = cellFileName(id);
      const fs::path tmp = dir_ / (g.file + ".tmp");
      const int fd = ::open(tmp.c_str(), O_WRONLY | O_CLOEXEC);
      if (fd < 0) fail(tmp, std::string("cannot reopen: ") + std::strerror(errno));
      if (::fdatasync(fd) != 0 && errno != EINVAL && errno != EROFS) {
        const int err = errno;
        ::close(fd);
        fail(tmp, std::string("flush failed: ") + std::strerror(err));
      }
      ::close(fd);
      if (::rename(tmp.c_str(), (dir_ / g.file).c_str()) != 0)
        fail(tmp, std::string("rename failed: ") + std::strerror(errno));
      r_.maxCellTriangles = std::max(r_.maxCellTriangles, c.triangles);
      m.cells.push_back(std::move(g));
    }
    m.triangles = r_.triangles;
    r_.cells = m.cells.size();
  }

 private:
  struct Cell {
    std::vector<uint8_t> buf;
    uint64_t triangles = 0;
    bool created = false;
  };

  // Makes room in cell id's buffer for one more record, within the budget.
  void grow(uint32_t id, size_t rec) {
    Cell& c = cells_[id];
    const uint64_t minCap = rec * 64;
    uint64_t newCap = std::max<uint64_t>(minCap, std::min<uint64_t>(2 * c.buf.capacity(), budget_ / 4));
    if (newCap <= c.buf.capacity()) {
      flushCell(id);  // already at its largest share: write it out and start again
      newCap = minCap;
    }
    uint64_t growth = newCap - c.buf.capacity();
    if (allocated_ + growth > budget_) {
      makeRoom(growth);
      if (c.buf.capacity() == 0)
        growth = newCap = minCap;  // it was flushed too
      else
        growth = newCap - c.buf.capacity();
    }
    const uint64_t before = c.buf.capacity();
    c.buf.reserve(static_cast<size_t>(newCap));
    allocated_ += c.buf.capacity() - before;
    active_.push_back(id);  // may repeat; makeRoom deduplicates
    r_.peakBufferedBytes = std::max(r_.peakBufferedBytes, allocated_);
  }

  // Flushes the largest buffers until `growth` more bytes fit in half the budget.
  void makeRoom(uint64_t growth) {
    ++r_.flushRounds;
    std::sort(active_.begin(), active_.end());
    active_.erase(std::unique(active_.begin(), active_.end()), active_.end());
    std::erase_if(active_, [&](uint32_t id) { return cells_[id].buf.capacity() == 0; });
    std::sort(active_.begin(), active_.end(),
              [&](uint32_t a, uint32_t b) { return cells_[a].buf.capacity() > cells_[b].buf.capacity(); });
    size_t k = 0;
    while (k < active_.size() && allocated_ + growth > budget_ / 2) flushCell(active_[k++]);
    active_.erase(active_.begin(), active_.begin() + static_cast<ptrdiff_t>(k));
  }

  // Appends a cell's buffer to its file and releases the buffer's memory.
  void flushCell(uint32_t id) {
    Cell& c = cells_[id];
    if (!c.buf.empty()) {
      const fs::path tmp = dir_ / (cellFileName(id) + ".tmp");
      const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
      if (fd < 0) fail(tmp, std::string("cannot create: ") + std::strerror(errno));
      if (!c.created) {
        uint8_t header[kCellHeaderBytes] = {};
        std::memcpy(header, kCellMagic, 4);
        const uint32_t words[3] = {kGridFormatVersion, r_.manifest.recordBytes, 0};
        std::memcpy(header + 4, words, sizeof words);
        writeAll(fd, header, sizeof header, tmp);
        r_.bytesWritten += sizeof header;
        c.created = true;
      }
      writeAll(fd, c.buf.data(), c.buf.size(), tmp);
      if (::close(fd) != 0) fail(tmp, std::string("close failed: ") + std::strerror(errno));
      r_.bytesWritten += c.buf.size();
      ++r_.cellWrites;
    }
    allocated_ -= c.buf.capacity();
    std::vector<uint8_t>().swap(c.buf);
  }

  fs::path dir_;
  const GridifyOptions& o_;
  const MeshInfo* probed_;
  GridifyResult& r_;
  uint64_t budget_ = 0, allocated_ = 0;
  std::vector<Cell> cells_;
  std::vector<uint32_t> active_;  // cells that may hold a buffer
};

nlohmann::ordered_json manifestJson(const GridManifest& m, const GridifyResult& r) {
  using ojson = nlohmann::ordered_json;
  ojson cells = ojson::array();
  for (const GridCell& c : m.cells)
    cells.push_back({{"id", c.id}, {"coord", c.coord}, {"triangles", c.triangles}, {"file", c.file}});
  ojson j;
  j["format"] = kGridFormatTag;
  j["version"] = m.version;
  j["source"] = m.source;
  j["origin"] = m.origin;
  j["cellSize"] = m.cellSize;
  j["dims"] = m.dims;
  j["hasColours"] = m.hasColours;
  j["recordBytes"] = m.recordBytes;
  j["triangles"] = m.triangles;
  j["bounds"] = {{"min", {m.bounds.min.x, m.bounds.min.y, m.bounds.min.z}},
                 {"max", {m.bounds.max.x, m.bounds.max.y, m.bounds.max.z}}};
  j["repairs"] = {{"trianglesRead", m.trianglesRead},
                  {"droppedNonFinite", m.droppedNonFinite},
                  {"droppedDegenerate", m.droppedDegenerate},
                  {"droppedDuplicate", m.droppedDuplicate},
                  {"duplicateCheckComplete", m.duplicateCheckComplete}};
  j["stats"] = {{"format", r.read.info.formatName},
                {"vertices", r.read.vertices},
                {"maxCellTriangles", r.maxCellTriangles},
                {"bufferBudgetBytes", r.bufferBudgetBytes},
                {"peakBufferedBytes", r.peakBufferedBytes},
                {"peakTrackedBytes", r.peakTrackedBytes},
                {"flushRounds", r.flushRounds},
                {"cellWrites", r.cellWrites},
                {"bytesWritten", r.bytesWritten},
                {"seconds", r.seconds}};
  j["cells"] = std::move(cells);
  return j;
}

}  // namespace

std::array<uint32_t, 3> GridManifest::cellOf(const MeshTriangle& t) const {
  std::array<uint32_t, 3> c;
  for (int a = 0; a < 3; ++a) {
    const double centroid = (double(t.p[0][a]) + t.p[1][a] + t.p[2][a]) / 3.0;
    const double x = std::floor((centroid - origin[a]) / cellSize[a]);
    c[a] = x <= 0 ? 0u : x >= dims[a] - 1 ? dims[a] - 1 : static_cast<uint32_t>(x);
  }
  return c;
}

std::array<std::array<double, 3>, 2> GridManifest::cellBox(const std::array<uint32_t, 3>& c) const {
  std::array<std::array<double, 3>, 2> b;
  for (int a = 0; a < 3; ++a) {
    b[0][a] = origin[a] + c[a] * cellSize[a];
    b[1][a] = origin[a] + (c[a] + 1.0) * cellSize[a];
  }
  return b;
}

std::array<uint32_t, 3> chooseGridDims(const MeshBounds& bounds, uint64_t triangles, uint32_t targetPerCell,
                                       uint64_t maxCells) {
  std::array<uint32_t, 3> dims{1, 1, 1};
  if (bounds.empty() || targetPerCell == 0 || maxCells == 0) return dims;
  const double k = std::ceil(double(triangles) / targetPerCell);
  if (k <= 1) return dims;
  double e[3];
  for (int a = 0; a < 3; ++a) e[a] = double(bounds.max[a]) - bounds.min[a];
  const double area = e[0] * e[1] + e[1] * e[2] + e[2] * e[0];
  const double diag = std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
  if (!(diag > 0) || !std::isfinite(diag)) return dims;
  double side = area > 0 ? std::sqrt(area / k) : diag / k;
  for (;;) {  // ends: side grows until every axis has one cell
    uint64_t total = 1;
    for (int a = 0; a < 3; ++a) {
      const double n = std::ceil(e[a] / side);
      dims[a] = n <= 1 ? 1u : n >= kMaxCellsPerAxis ? kMaxCellsPerAxis : static_cast<uint32_t>(n);
      total *= dims[a];
    }
    if (total <= maxCells) break;
    side *= std::max(1.05, pmath::cbrt(double(total) / double(maxCells)));
  }
  return dims;
}

namespace {

GridifyResult gridifyStaged(const fs::path& mesh, const fs::path& outDir, const GridifyOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  validate(options);
  GridifyResult result;
  MeshReadOptions ro = options.read;
  ro.maxVertexBytes = options.maxMemoryBytes / 4;
  ro.duplicateSetBytes = options.maxMemoryBytes / 8;

  // OBJ and STL do not list all vertices before the faces: a pre-pass finds the bounds.
  const MeshInfo kind = detectMesh(mesh);
  MeshInfo probed;
  if (kind.format == MeshFormat::kObj || kind.format == MeshFormat::kStl) {
    probed = probeMesh(mesh, ro);
    result.probed = true;
  }

  StagedDirectory stage(outDir, kGridManifestName, "grid");
  GridWriter writer(stage.path(), options, result.probed ? &probed : nullptr, result);
  result.read = streamMesh(mesh, writer, ro);
  const MeshReadStats& rs = result.read;
  if (rs.trianglesOut == 0)
    fail(mesh, "no valid triangles (" + std::to_string(rs.trianglesRead) + " read: " +
                   std::to_string(rs.droppedNonFinite) + " non-finite, " + std::to_string(rs.droppedDegenerate) +
                   " degenerate, " + std::to_string(rs.droppedDuplicate) + " duplicate)");
  writer.finish();

  GridManifest& m = result.manifest;
  m.source = fs::absolute(mesh).string();
  m.trianglesRead = rs.trianglesRead;
  m.droppedNonFinite = rs.droppedNonFinite;
  m.droppedDegenerate = rs.droppedDegenerate;
  m.droppedDuplicate = rs.droppedDuplicate;
  m.duplicateCheckComplete = rs.duplicateCheckComplete;
  result.peakTrackedBytes = rs.vertexArrayBytes + rs.duplicateSetBytes + result.peakBufferedBytes +
                            writer.cellTableBytes() + uint64_t{ro.chunkTriangles} * sizeof(MeshTriangle);
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::string text = manifestJson(m, result).dump(1) + "\n";
  atomicWriteFile(stage.path() / kGridManifestName, text.data(), text.size());
  stage.commit();
  return result;
}

}  // namespace

GridifyResult gridify(const fs::path& mesh, const fs::path& outDir, const GridifyOptions& options) {
  GridifyResult result = gridifyStaged(mesh, outDir, options);
  // The cell buffers were many blocks of up to a few MiB in the heap; glibc keeps such freed
  // pages unless asked, and the next stage would start with them still counted in its RSS.
  releaseFreedMemory();
  return result;
}

GridManifest readGridManifest(const fs::path& dir) {
  const fs::path file = dir / kGridManifestName;
  std::ifstream in(file, std::ios::binary);
  if (!in) fail(file, "cannot open (not a grid directory?)");
  GridManifest m;
  try {
    const nlohmann::json j = nlohmann::json::parse(in);
    if (!j.is_object() || j.value("format", "") != kGridFormatTag)
      fail(file, std::string("not a gimlod grid manifest (\"format\" must be \"") + kGridFormatTag + "\")");
    m.version = j.at("version").get<uint32_t>();
    if (m.version < 1 || m.version > kGridFormatVersion)
      fail(file, "unsupported grid format version " + std::to_string(m.version));
    m.source = j.at("source").get<std::string>();
    m.origin = j.at("origin").get<std::array<double, 3>>();
    m.cellSize = j.at("cellSize").get<std::array<double, 3>>();
    m.dims = j.at("dims").get<std::array<uint32_t, 3>>();
    m.hasColours = j.at("hasColours").get<bool>();
    m.recordBytes = j.at("recordBytes").get<uint32_t>();
    m.triangles = j.at("triangles").get<uint64_t>();
    const auto& b = j.at("bounds");
    const auto lo = b.at("min").get<std::array<float, 3>>();
    const auto hi = b.at("max").get<std::array<float, 3>>();
    m.bounds.min = {lo[0], lo[1], lo[2]};
    m.bounds.max = {hi[0], hi[1], hi[2]};
    const auto& rep = j.at("repairs");
    m.trianglesRead = rep.at("trianglesRead").get<uint64_t>();
    m.droppedNonFinite = rep.at("droppedNonFinite").get<uint64_t>();
    m.droppedDegenerate = rep.at("droppedDegenerate").get<uint64_t>();
    m.droppedDuplicate = rep.at("droppedDuplicate").get<uint64_t>();
    m.duplicateCheckComplete = rep.at("duplicateCheckComplete").get<bool>();
    for (const auto& c : j.at("cells")) {
      GridCell g;
      g.id = c.at("id").get<uint32_t>();
      g.coord = c.at("coord").get<std::array<uint32_t, 3>>();
      g.triangles = c.at("triangles").get<uint64_t>();
      g.file = c.at("file").get<std::string>();
      m.cells.push_back(std::move(g));
    }
  } catch (const nlohmann::json::exception& e) {
    fail(file, std::string("invalid grid manifest: ") + e.what());
  }
  if (m.recordBytes != (m.hasColours ? 48u : 36u))
    fail(file, "recordBytes " + std::to_string(m.recordBytes) + " does not match hasColours");
  uint64_t cells = 1, sum = 0;
  for (int a = 0; a < 3; ++a) {
    if (m.dims[a] == 0 || m.dims[a] > kMaxCellsPerAxis) fail(file, "bad grid dims");
    if (!(m.cellSize[a] > 0) || !std::isfinite(m.cellSize[a]) || !std::isfinite(m.origin[a]))
      fail(file, "bad cell size or origin");
    cells *= m.dims[a];
  }
  for (const GridCell& c : m.cells) {
    if (c.id >= cells || m.cellId(c.coord) != c.id || c.coord[0] >= m.dims[0] || c.coord[1] >= m.dims[1] ||
        c.coord[2] >= m.dims[2])
      fail(file, "cell " + std::to_string(c.id) + " is outside the grid or has a wrong coord");
    if (c.file != cellFileName(c.id))
      fail(file, "cell " + std::to_string(c.id) + " has an unexpected file name '" + c.file + "'");
    sum += c.triangles;
  }
  if (sum != m.triangles)
    fail(file, "cell triangle counts add up to " + std::to_string(sum) + ", not " + std::to_string(m.triangles));
  return m;
}

std::vector<MeshTriangle> readCell(const fs::path& dir, const GridManifest& m, const GridCell& cell) {
  const fs::path file = dir / cell.file;
  std::ifstream in(file, std::ios::binary);
  if (!in) fail(file, "cannot open cell file");
  std::error_code ec;
  const uint64_t size = fs::file_size(file, ec);
  const uint64_t want = kCellHeaderBytes + cell.triangles * m.recordBytes;
  if (ec || size != want)
    fail(file, "cell file has " + std::to_string(size) + " bytes; " + std::to_string(cell.triangles) +
                   " triangles need " + std::to_string(want));
  uint8_t header[kCellHeaderBytes];
  in.read(reinterpret_cast<char*>(header), sizeof header);
  uint32_t words[3];
  std::memcpy(words, header + 4, sizeof words);
  if (!in || std::memcmp(header, kCellMagic, 4) != 0 || words[0] != kGridFormatVersion || words[1] != m.recordBytes)
    fail(file, "bad cell file header");
  std::vector<uint8_t> bytes(static_cast<size_t>(cell.triangles * m.recordBytes));
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (!in) fail(file, "cell file read failed");
  std::vector<MeshTriangle> tris(static_cast<size_t>(cell.triangles));
  const glm::u8vec4 white{255, 255, 255, 255};
  for (size_t i = 0; i < tris.size(); ++i) {
    const uint8_t* p = bytes.data() + i * m.recordBytes;
    MeshTriangle& t = tris[i];
    std::memcpy(t.p.data(), p, 36);
    if (m.hasColours)
      std::memcpy(t.c.data(), p + 36, 12);
    else
      t.c = {white, white, white};
    t.v = {kNoVertex, kNoVertex, kNoVertex};
  }
  return tris;
}

}  // namespace gimlod
