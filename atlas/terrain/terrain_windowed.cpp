#include "atlas/terrain/terrain_windowed.h"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <fcntl.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include "atlas/terrain/void_fill.h"
#include "core/block_codec.h"
#include "core/progress.h"

namespace gimlod {

namespace fs = std::filesystem;

namespace {

// A raw scratch file of fixed-size elements in rows, read and written at any offset; removed when
// destroyed.
class ScratchFile {
 public:
  ScratchFile(fs::path path, const fs::path& dem) : path_(std::move(path)), dem_(dem) {
    fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd_ < 0) fail("cannot create the scratch file " + path_.string());
  }
  ~ScratchFile() {
    if (fd_ >= 0) ::close(fd_);
    std::error_code ec;
    fs::remove(path_, ec);
  }
  ScratchFile(const ScratchFile&) = delete;
  ScratchFile& operator=(const ScratchFile&) = delete;
  void write(uint64_t offset, const void* data, size_t bytes) {
    const char* p = static_cast<const char*>(data);
    while (bytes > 0) {
      const ssize_t n = ::pwrite(fd_, p, bytes, off_t(offset));
      if (n <= 0) {
        if (n < 0 && errno == EINTR) continue;
        fail("cannot write the scratch file " + path_.string() + " (" + std::strerror(errno) + "; disk full?)");
      }
      p += n, offset += uint64_t(n), bytes -= size_t(n);
    }
  }
  void read(uint64_t offset, void* data, size_t bytes) const {
    char* p = static_cast<char*>(data);
    while (bytes > 0) {
      const ssize_t n = ::pread(fd_, p, bytes, off_t(offset));
      if (n <= 0) {
        if (n < 0 && errno == EINTR) continue;
        fail("cannot read the scratch file " + path_.string());
      }
      p += n, offset += uint64_t(n), bytes -= size_t(n);
    }
  }
  uint64_t size() const {
    std::error_code ec;
    const auto s = fs::file_size(path_, ec);
    return ec ? 0 : uint64_t(s);
  }

 private:
  [[noreturn]] void fail(const std::string& what) const { throw InputError(dem_.string() + ": " + what); }
  fs::path path_, dem_;
  int fd_ = -1;
};

}  // namespace

WindowedTerrainResult writeTerrainChartsWindowed(const DemSource& source, const fs::path& dir,
                                                 const WindowedTerrainOptions& options, AtlasManifest& manifest) {
  const auto start = std::chrono::steady_clock::now();
  validateTerrainAtlasOptions(options.atlas);
  WindowedTerrainResult r;
  r.dem = source.info();
  DemRaster& dem = r.dem;
  const fs::path input = manifest.source.empty() ? fs::path("DEM") : fs::path(manifest.source);
  const uint64_t width = dem.width, height = dem.height;
  const uint64_t budget = std::max<uint64_t>(options.memoryBytes, uint64_t{16} << 20);

  // 1. Read: bands of rows into the scratch raster (heights, and a validity byte per sample).
  ScratchFile heights(dir / ".dem_heights.scratch", input), valid(dir / ".dem_valid.scratch", input);
  uint64_t voids = 0;
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  dem.integerHeights = true;
  {
    const uint64_t rowsPerBand = std::clamp<uint64_t>(budget / 4 / (width * 5), 1, height);
    std::vector<float> h(rowsPerBand * width);
    std::vector<uint8_t> v(rowsPerBand * width);
    const progress::ProgressStage stage("read DEM", height);
    for (uint64_t y0 = 0; y0 < height; y0 += rowsPerBand) {
      const uint64_t rows = std::min(rowsPerBand, height - y0);
      const size_t n = size_t(rows * width);
      source.readRows(uint32_t(y0), uint32_t(rows), h.data(), v.data());
      for (size_t i = 0; i < n; ++i) {
        if (!v[i]) {
          ++voids;
          h[i] = 0.f;
          continue;
        }
        lo = std::min(lo, h[i]);
        hi = std::max(hi, h[i]);
        dem.integerHeights = dem.integerHeights && h[i] == std::nearbyint(h[i]);
      }
      heights.write(y0 * width * 4, h.data(), n * 4);
      valid.write(y0 * width, v.data(), n);
      progress::advance(rows);
    }
  }
  if (voids == width * height) throw InputError(input.string() + ": every sample is nodata (" +
                                                std::to_string(voids) + " samples)");
  r.scratchBytes = heights.size() + valid.size();

  // 2. Voids, window by window.
  dem.voidsFilled = voids;
  dem.voidFillMethod = kVoidFillMethod;
  if (voids > 0) {
    WindowedFill io;
    io.read = [&](const CellWindow& w, float* h, uint8_t* ok) {
      const size_t ww = size_t(w.width());
      for (int64_t y = w.y0; y < w.y1; ++y) {
        const uint64_t at = uint64_t(y) * width + uint64_t(w.x0);
        heights.read(at * 4, h + size_t(y - w.y0) * ww, ww * 4);
        valid.read(at, ok + size_t(y - w.y0) * ww, ww);
      }
    };
    io.write = [&](const CellWindow& w, const float* h) {
      const size_t ww = size_t(w.width());
      for (int64_t y = w.y0; y < w.y1; ++y)
        heights.write((uint64_t(y) * width + uint64_t(w.x0)) * 4, h + size_t(y - w.y0) * ww, ww * 4);
    };
    std::vector<uint8_t> row;
    io.hasVoids = [&](const CellWindow& w) {
      row.resize(size_t(w.width()));
      for (int64_t y = w.y0; y < w.y1; ++y) {
        valid.read(uint64_t(y) * width + uint64_t(w.x0), row.data(), row.size());
        if (std::find(row.begin(), row.end(), uint8_t{0}) != row.end()) return true;
      }
      return false;
    };
    // A window's levels, copies and flags take about 16 bytes per level-0 sample.
    fillVoidsWindowed(dem.width, dem.height, lo, hi, io, std::max<uint64_t>(budget / 4 / 16, 1u << 18));
  }

  // 3. Heights as a compressed atlas stores them (quantized like the in-memory build), and their
  // range.
  const bool compressed = options.atlas.coding.compressed;
  if (compressed)
    r.heightPrecision = terrainHeightPrecision(input, options.heightPrecision, dem.integerHeights,
                                               options.defaultHeightPrecision, lo, hi);
  {
    const uint64_t rowsPerBand = std::clamp<uint64_t>(budget / 4 / (width * 4), 1, height);
    std::vector<float> h(rowsPerBand * width);
    float qlo = std::numeric_limits<float>::infinity(), qhi = -qlo;
    for (uint64_t y0 = 0; y0 < height; y0 += rowsPerBand) {
      const uint64_t rows = std::min(rowsPerBand, height - y0);
      const size_t n = size_t(rows * width);
      heights.read(y0 * width * 4, h.data(), n * 4);
      if (compressed)
        for (size_t i = 0; i < n; ++i) h[i] = storedHeight(h[i], r.heightPrecision);
      for (size_t i = 0; i < n; ++i) qlo = std::min(qlo, h[i]), qhi = std::max(qhi, h[i]);
      if (compressed) heights.write(y0 * width * 4, h.data(), n * 4);
    }
    dem.minHeight = qlo;
    dem.maxHeight = qhi;
  }

  // 4. Charts, a chart row at a time, from the rows it reads.
  TerrainAtlasOptions atlas = options.atlas;
  atlas.coding.heightPrecision = r.heightPrecision;
  fillTerrainManifest(dem, atlas, manifest);
  manifest.compression = CompressionInfo{};
  if (compressed) {
    manifest.compression.present = true;
    manifest.compression.heightPrecision = r.heightPrecision;
  }
  fs::create_directories(dir / "charts");
  const uint32_t cs = atlas.chartSize;
  const uint64_t bandRows = uint64_t(3) * (cs - 1) + 1;
  if (bandRows * width * 4 > budget / 2)
    throw InputError(input.string() + ": a chart row of " + std::to_string(width) + " x " + std::to_string(bandRows) +
                     " samples needs " + std::to_string((bandRows * width * 4) >> 20) + " MiB, over half the " +
                     std::to_string(budget >> 20) + " MiB the windows may use; give a smaller " +
                     optionRef("chartSize") + " or a larger " + optionRef("maxMemory"));
  uint64_t perChart = 0;
  for (uint32_t k = 0; k <= manifest.intervalsLog2(); ++k) {
    const uint64_t s = ((cs - 1) >> k) + 1;
    perChart += s * s;
  }
  // A chart in flight holds its pyramid with ring heights and its file image: about 20 bytes per
  // stored sample.
  const int concurrency = int(std::clamp<uint64_t>((budget / 2) / std::max<uint64_t>(perChart * 20, 1), 1,
                                                   uint64_t(tbb::this_task_arena::max_concurrency())));
  tbb::task_arena arena(concurrency);
  std::vector<float> band;
  std::atomic<uint64_t> bytes{0};
  const progress::ProgressStage stage("charts", manifest.charts.size());
  for (uint32_t gy = 0; gy < manifest.chartsY; ++gy) {
    const auto span = chartRowSpan(gy, cs, int64_t(height));
    const uint64_t rows = uint64_t(span[1] - span[0]);
    r.bandRows = std::max(r.bandRows, rows);
    band.resize(size_t(rows * width));
    heights.read(uint64_t(span[0]) * width * 4, band.data(), band.size() * 4);
    DemRows view;
    view.heights = band.data();
    view.y0 = span[0];
    view.rows = int64_t(rows);
    view.width = int64_t(width);
    view.height = int64_t(height);
    view.spacing = dem.spacing;
    arena.execute([&] {
      tbb::parallel_for(uint32_t{0}, manifest.chartsX, [&](uint32_t gx) {
        const ChartInfo& c = manifest.charts[size_t(gy) * manifest.chartsX + gx];
        const ChartPyramid p = buildChartPyramid(view, c.gridX, c.gridY, cs, compressed);
        bytes += writeChartFile(dir / c.file, p, cs, atlas.blockIntervals, atlas.coding);
        progress::advance();
      });
    });
  }
  r.charts.charts = uint32_t(manifest.charts.size());
  r.charts.samples = width * height;
  r.charts.storedSamples = perChart * r.charts.charts;
  r.charts.bytesOnDisk = bytes.load();
  r.charts.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

}  // namespace gimlod
