#include "runtime/page_reader.h"

namespace gimlod {

PageReader::PageReader(const std::filesystem::path& atlasDir, const AtlasManifest& manifest,
                       const HierarchyParams& params)
    : params_(params), geometry_(manifest.kind == AtlasKind::Geometry) {
  for (const ChartInfo& c : manifest.charts) {
    charts_.push_back(std::make_unique<ChartFileReader>(atlasDir / c.file));
    if (!charts_.back()->hasChannel(geometry_ ? kChannelPositions : kChannelHeights))
      throw InputError((atlasDir / c.file).string() + ": has no " + (geometry_ ? "positions" : "heights") +
                       " for a " + atlasKindName(manifest.kind) + " atlas");
  }
  if (manifest.imagery.present) {
    // Terrain imagery: one attribute file per chart on the refined lattice.
    colourScaleLog2_ = manifest.imagery.scaleLog2;
    const uint32_t size = manifest.imagery.chartSize(manifest.chartSize);
    const uint32_t block = manifest.blockIntervals << colourScaleLog2_;
    for (const ChartInfo& c : manifest.charts) {
      const std::filesystem::path file = atlasDir / c.imageryFile;
      imagery_.push_back(std::make_unique<ChartFileReader>(file));
      const ChartFileReader& r = *imagery_.back();
      if (!r.hasChannel(kChannelColours) || r.chartSize() != size || r.blockIntervals() != block ||
          r.levels() < manifest.intervalsLog2() + 1)
        throw InputError(file.string() + ": not the chart's imagery (expected colours, " + std::to_string(size) +
                         " samples, blocks of " + std::to_string(block) + ", " +
                         std::to_string(manifest.intervalsLog2() + 1) + " levels)");
    }
    colours_ = true;
    return;
  }
  colours_ = !charts_.empty();
  for (const auto& c : charts_) colours_ = colours_ && c->hasChannel(kChannelColours);
}

void PageReader::read(const NodeId& n, std::vector<float>& samples, std::vector<PackedNormal>& normals,
                      std::vector<PackedColour>* colours) const {
  const uint32_t L = params_.intervalsLog2;
  const uint32_t r = params_.maxRes(n.level);
  const uint32_t k = params_.pyramidLevel(n.level, r);
  const uint32_t size = 1u << (L - n.level);  // level-0 intervals
  const uint32_t u0 = (n.x * size) >> k, v0 = (n.y * size) >> k;
  const uint32_t s = (1u << r) + 1;
  samples.resize(size_t(s) * s * (geometry_ ? 3 : 1));
  normals.resize(size_t(s) * s);
  if (geometry_)
    charts_[n.chart]->readPositions(k, u0, v0, 1u << r, reinterpret_cast<glm::vec3*>(samples.data()));
  else
    charts_[n.chart]->readHeights(k, u0, v0, 1u << r, samples.data());
  charts_[n.chart]->readNormals(k, u0, v0, 1u << r, normals.data());
  bytesRead_ += samples.size() * sizeof(float) + normals.size() * sizeof(PackedNormal);
  if (colours) {
    colours->clear();
    if (colours_) {
      const uint32_t d = colourScaleLog2_;
      const size_t cs = (size_t(1) << (r + d)) + 1;
      colours->resize(cs * cs);
      const ChartFileReader& file = imagery_.empty() ? *charts_[n.chart] : *imagery_[n.chart];
      file.readColours(k, u0 << d, v0 << d, 1u << (r + d), colours->data());
      bytesRead_ += colours->size() * sizeof(PackedColour);
    }
  }
}

}  // namespace gimlod
