#include "runtime/page_reader.h"

#include <algorithm>

#include <sys/resource.h>

namespace gimlod {

ChartFileSet::ChartFileSet(size_t maxOpen) : maxOpen_(std::max<size_t>(maxOpen, 1)) {}

void ChartFileSet::add(std::filesystem::path path) {
  paths_.push_back(std::move(path));
  open_.emplace_back();
  lastUse_.push_back(0);
}

std::shared_ptr<const ChartFileReader> ChartFileSet::get(uint32_t i) const {
  std::lock_guard<std::mutex> lock(mutex_);
  lastUse_[i] = ++clock_;
  if (open_[i]) return open_[i];
  if (openCount_ >= maxOpen_) {
    // Close the least recently used (a reader still held elsewhere closes when released).
    size_t oldest = i;
    for (size_t j = 0; j < open_.size(); ++j)
      if (open_[j] && (oldest == i || lastUse_[j] < lastUse_[oldest])) oldest = j;
    if (oldest != i) {
      open_[oldest].reset();
      --openCount_;
    }
  }
  open_[i] = std::make_shared<const ChartFileReader>(paths_[i]);
  ++openCount_;
  return open_[i];
}

size_t ChartFileSet::openFiles() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return openCount_;
}

size_t chartFilesKeptOpen() {
  rlimit l{};
  const size_t limit = ::getrlimit(RLIMIT_NOFILE, &l) == 0 && l.rlim_cur != RLIM_INFINITY ? size_t(l.rlim_cur) : 4096;
  return std::clamp<size_t>(limit / 4, 16, 2048);
}

PageReader::PageReader(const std::filesystem::path& atlasDir, const AtlasManifest& manifest,
                       const HierarchyParams& params)
    : params_(params),
      geometry_(manifest.kind == AtlasKind::Geometry),
      charts_(chartFilesKeptOpen()),
      imagery_(chartFilesKeptOpen()) {
  // Every file is opened (and checked) once here; beyond chartFilesKeptOpen() they close again
  // and reopen when read.
  bool allColours = !manifest.charts.empty();
  for (const ChartInfo& c : manifest.charts) {
    charts_.add(atlasDir / c.file);
    finest_.push_back(c.finestLevel);
    const auto reader = charts_.get(uint32_t(charts_.size() - 1));
    allColours = allColours && reader->hasChannel(kChannelColours);
    const uint32_t size = manifest.chartFileSize(c.id);
    if (reader->chartSize() != size || reader->levels() != manifest.pyramidLevels() - c.finestLevel)
      throw InputError((atlasDir / c.file).string() + ": holds charts of " + std::to_string(reader->chartSize()) +
                       " samples and " + std::to_string(reader->levels()) + " levels, the manifest says " +
                       std::to_string(size) + " and " + std::to_string(manifest.pyramidLevels() - c.finestLevel));
    if (!reader->hasChannel(geometry_ ? kChannelPositions : kChannelHeights))
      throw InputError((atlasDir / c.file).string() + ": has no " + (geometry_ ? "positions" : "heights") + " for a " +
                       atlasKindName(manifest.kind) + " atlas");
  }
  if (manifest.imagery.present) {
    // Terrain imagery: one attribute file per chart on the refined lattice.
    colourScaleLog2_ = manifest.imagery.scaleLog2;
    const uint32_t size = manifest.imagery.chartSize(manifest.chartSize);
    const uint32_t block = manifest.blockIntervals << colourScaleLog2_;
    for (const ChartInfo& c : manifest.charts) {
      const std::filesystem::path file = atlasDir / c.imageryFile;
      imagery_.add(file);
      const auto reader = imagery_.get(uint32_t(imagery_.size() - 1));
      const ChartFileReader& r = *reader;
      if (!r.hasChannel(kChannelColours) || r.chartSize() != size || r.blockIntervals() != block ||
          r.levels() < manifest.intervalsLog2() + 1)
        throw InputError(file.string() + ": not the chart's imagery (expected colours, " + std::to_string(size) +
                         " samples, blocks of " + std::to_string(block) + ", " +
                         std::to_string(manifest.intervalsLog2() + 1) + " levels)");
    }
    colours_ = true;
    return;
  }
  colours_ = allColours;
}

void PageReader::read(const NodeId& n, std::vector<float>& samples, std::vector<PackedNormal>& normals,
                      std::vector<PackedColour>* colours) const {
  // In the chart file's own units: its level 0 is the atlas's level finest_[chart].
  const uint32_t L = params_.intervalsLog2 - finest_[n.chart];
  const uint32_t r = pageResLog2(n);
  const uint32_t k = L - n.level - r;
  const uint32_t size = 1u << (L - n.level);  // the file's level-0 intervals
  const uint32_t u0 = (n.x * size) >> k, v0 = (n.y * size) >> k;
  const uint32_t s = (1u << r) + 1;
  samples.resize(size_t(s) * s * (geometry_ ? 3 : 1));
  normals.resize(size_t(s) * s);
  const auto chart = charts_.get(n.chart);
  if (geometry_)
    chart->readPositions(k, u0, v0, 1u << r, reinterpret_cast<glm::vec3*>(samples.data()));
  else
    chart->readHeights(k, u0, v0, 1u << r, samples.data());
  chart->readNormals(k, u0, v0, 1u << r, normals.data());
  bytesRead_ += samples.size() * sizeof(float) + normals.size() * sizeof(PackedNormal);
  if (colours) {
    colours->clear();
    if (colours_) {
      const uint32_t d = colourScaleLog2_;
      const size_t cs = (size_t(1) << (r + d)) + 1;
      colours->resize(cs * cs);
      const auto file = imagery_.empty() ? chart : imagery_.get(n.chart);
      file->readColours(k, u0 << d, v0 << d, 1u << (r + d), colours->data());
      bytesRead_ += colours->size() * sizeof(PackedColour);
    }
  }
}

}  // namespace gimlod
