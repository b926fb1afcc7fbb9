// Overlays of the drawn cut: per node, a colour that tells the charts (or levels, or resolutions)
// apart and which of its sides lie on a chart border (a seam) or an open one (the input's own
// border), for the fragment shader to draw over the shading. For atlas inspection and the viewer.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string_view>
#include <vector>

#include "hierarchy/hierarchy.h"
#include "runtime/cut.h"

namespace gimlod {

enum class OverlayMode : uint8_t {
  kNone,        // plain shading
  kChart,       // each chart its own colour, seams dark, open borders red
  kLevel,       // colour by quadtree level
  kResolution,  // colour by drawn resolution
  kError,       // screen-space error against a scale (heatColour: blue 0, green half, red at or above it)
  kCustom,      // a colour per node given by the caller (e.g. a heat map of some figure)
};

// A node's colour for kCustom (RGBA8, red in the low byte).
using NodeColour = std::function<uint32_t(const NodeId&)>;

// "none", "chart", "level", "res", "error" ("custom" is not parsed: it needs colours).
const char* overlayModeName(OverlayMode mode);
std::optional<OverlayMode> parseOverlayMode(std::string_view name);

// One node's overlay as the shader reads it (std430 uvec4). Sides: bit s for side s (0 bottom
// v = 0, 1 right, 2 top, 3 left).
struct NodeOverlay {
  uint32_t rgba = 0;              // RGBA8, red in the low byte (GLSL unpackUnorm4x8)
  uint32_t chartBorderSides = 0;  // sides on the chart's border
  uint32_t openSides = 0;         // of those, the ones without a neighbouring chart
  uint32_t flags = 0;             // kOverlayStandIn
};
static_assert(sizeof(NodeOverlay) == 16);
// NodeOverlay::flags: the node is drawn from its own resident page, standing in for finer desired
// nodes whose pages are still loading (asynchronous loading; the "pages loading" view).
inline constexpr uint32_t kOverlayStandIn = 1;

// The heat ramp for t in [0, 1]: blue, green, red (t clamped).
std::array<uint8_t, 3> heatColour(double t);

// A colour for chart `chart`: hues spread by the golden angle, so neighbours differ.
uint32_t chartColour(uint32_t chart);

// The overlay of every cut node, in cut order; empty for kNone. kCustom takes its colours from
// `colour` (std::invalid_argument without one). kError colours each node by its CutNode::errorPx
// over errorScalePx (the tolerance in error mode); errorScalePx <= 0 takes the cut's largest error.
std::vector<NodeOverlay> nodeOverlays(const Hierarchy& h, const Cut& cut, OverlayMode mode,
                                      const NodeColour& colour = {}, double errorScalePx = 0.0);

}  // namespace gimlod
