#include "runtime/overlay.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "core/atlas_format.h"

namespace gimlod {
namespace {

uint32_t packRgb(double r, double g, double b) {
  const auto u = [](double x) { return uint32_t(std::lround(std::clamp(x, 0.0, 1.0) * 255.0)); };
  return u(r) | u(g) << 8 | u(b) << 16 | 255u << 24;
}

uint32_t hsv(double h, double s, double v) {
  h = h - std::floor(h);
  const double i = std::floor(h * 6.0), f = h * 6.0 - i;
  const double p = v * (1 - s), q = v * (1 - f * s), t = v * (1 - (1 - f) * s);
  switch (int(i) % 6) {
    case 0: return packRgb(v, t, p);
    case 1: return packRgb(q, v, p);
    case 2: return packRgb(p, v, t);
    case 3: return packRgb(p, q, v);
    case 4: return packRgb(t, p, v);
    default: return packRgb(v, p, q);
  }
}

// Eight clearly different colours for levels and resolutions.
uint32_t paletteColour(uint32_t i) {
  static const std::array<uint32_t, 8> kPalette = {
      packRgb(0.27, 0.47, 0.80), packRgb(0.30, 0.69, 0.42), packRgb(0.93, 0.75, 0.26), packRgb(0.91, 0.45, 0.22),
      packRgb(0.80, 0.26, 0.32), packRgb(0.58, 0.36, 0.75), packRgb(0.35, 0.78, 0.80), packRgb(0.60, 0.60, 0.60)};
  return kPalette[i % kPalette.size()];
}

}  // namespace

const char* overlayModeName(OverlayMode mode) {
  switch (mode) {
    case OverlayMode::kNone: return "none";
    case OverlayMode::kChart: return "chart";
    case OverlayMode::kLevel: return "level";
    case OverlayMode::kResolution: return "res";
    case OverlayMode::kError: return "error";
    case OverlayMode::kCustom: return "custom";
  }
  return "?";
}

std::optional<OverlayMode> parseOverlayMode(std::string_view name) {
  for (OverlayMode m :
       {OverlayMode::kNone, OverlayMode::kChart, OverlayMode::kLevel, OverlayMode::kResolution, OverlayMode::kError})
    if (name == overlayModeName(m)) return m;
  return std::nullopt;
}

std::array<uint8_t, 3> heatColour(double t) {
  t = std::clamp(t, 0.0, 1.0);
  const auto u = [](double x) { return uint8_t(std::lround(std::clamp(x, 0.0, 1.0) * 255.0)); };
  return {u(t < 0.5 ? 0.0 : 2.0 * t - 1.0), u(t < 0.5 ? 2.0 * t : 2.0 - 2.0 * t), u(t < 0.5 ? 1.0 - 2.0 * t : 0.0)};
}

uint32_t chartColour(uint32_t chart) {
  constexpr double kGolden = 0.6180339887498949;
  return hsv(0.11 + kGolden * double(chart), 0.45 + 0.2 * double(chart % 3) / 2.0, 0.92 - 0.12 * double(chart % 2));
}

std::vector<NodeOverlay> nodeOverlays(const Hierarchy& h, const Cut& cut, OverlayMode mode, const NodeColour& colour,
                                      double errorScalePx) {
  std::vector<NodeOverlay> out;
  if (mode == OverlayMode::kNone) return out;
  if (mode == OverlayMode::kCustom && !colour)
    throw std::invalid_argument("nodeOverlays: kCustom needs a colour per node");
  if (mode == OverlayMode::kError && !(errorScalePx > 0.0)) {
    errorScalePx = 0.0;
    for (const CutNode& n : cut.nodes) errorScalePx = std::max(errorScalePx, double(n.errorPx));
  }
  const auto heat = [&](float errorPx) {
    const std::array<uint8_t, 3> c = heatColour(errorScalePx > 0.0 ? double(errorPx) / errorScalePx : 0.0);
    return uint32_t(c[0]) | uint32_t(c[1]) << 8 | uint32_t(c[2]) << 16 | 0xFF000000u;
  };
  out.reserve(cut.nodes.size());
  for (const CutNode& n : cut.nodes) {
    NodeOverlay o;
    const NodeId& id = n.id;
    o.rgba = mode == OverlayMode::kChart    ? chartColour(id.chart)
             : mode == OverlayMode::kLevel  ? paletteColour(id.level)
             : mode == OverlayMode::kCustom ? colour(id)
             : mode == OverlayMode::kError  ? heat(n.errorPx)
                                            : paletteColour(n.resLog2);
    const uint32_t last = (1u << id.level) - 1;
    const std::array<bool, 4> onBorder = {id.y == 0, id.x == last, id.y == last, id.x == 0};
    for (uint32_t s = 0; s < 4; ++s) {
      if (!onBorder[s]) continue;
      o.chartBorderSides |= 1u << s;
      if (id.chart < h.roots.size() && h.roots[id.chart][s].chart < 0) o.openSides |= 1u << s;
    }
    out.push_back(o);
  }
  return out;
}

}  // namespace gimlod
