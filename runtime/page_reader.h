// Node pages read from the atlas blocks on disk (paper section 7.2). Pure C++.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <vector>

#include "core/atlas_format.h"
#include "hierarchy/hierarchy.h"

namespace gimlod {

// Reads node pages: a node's page is its finest-resolution window, (2^maxRes(level) + 1)^2
// samples of pyramid level intervalsLog2 - level - maxRes(level); every coarser resolution of the
// node is a subsampling of it. Thread-safe.
class PageReader {
 public:
  PageReader(const std::filesystem::path& atlasDir, const AtlasManifest& manifest,
             const HierarchyParams& params);
  uint32_t pageSamples(uint32_t level) const { return (1u << params_.maxRes(level)) + 1; }
  // samples: (pageSamples)^2 heights, or 3 floats (x, y, z) per sample for a geometry atlas.
  // colours, if given, receives the page's RGBA8 colours when the atlas has them (colours()):
  // (colourPageSamples)^2 texels, and is cleared otherwise.
  void read(const NodeId& n, std::vector<float>& samples, std::vector<PackedNormal>& normals,
            std::vector<PackedColour>* colours = nullptr) const;
  bool geometry() const { return geometry_; }
  // Every chart has colours: a mesh's vertex colours (in the chart file), or terrain imagery (an
  // attribute file per chart, at 2^colourScaleLog2 samples per geometry sample interval).
  bool colours() const { return colours_; }
  uint32_t colourScaleLog2() const { return colourScaleLog2_; }
  uint32_t colourPageSamples(uint32_t level) const { return (1u << (params_.maxRes(level) + colourScaleLog2_)) + 1; }
  uint64_t bytesRead() const { return bytesRead_; }

 private:
  HierarchyParams params_;
  bool geometry_ = false;
  bool colours_ = false;
  uint32_t colourScaleLog2_ = 0;
  std::vector<std::unique_ptr<ChartFileReader>> charts_;
  std::vector<std::unique_ptr<ChartFileReader>> imagery_;  // per chart, for terrain imagery
  mutable std::atomic<uint64_t> bytesRead_{0};
};

}  // namespace gimlod
