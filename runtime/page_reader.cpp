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
      colours->resize(size_t(s) * s);
      charts_[n.chart]->readColours(k, u0, v0, 1u << r, colours->data());
      bytesRead_ += colours->size() * sizeof(PackedColour);
    }
  }
}

}  // namespace gimlod
