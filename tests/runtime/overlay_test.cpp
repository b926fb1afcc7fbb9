// Per-node overlays (runtime/overlay.h): chart colours that tell neighbours apart, and the sides on
// a chart border and on an open one, on a hand-made two-chart layout.
#include <gtest/gtest.h>

#include <set>

#include "runtime/overlay.h"

namespace gimlod {
namespace {

// Two charts side by side: chart 0's right edge meets chart 1's left edge; every other edge open.
Hierarchy twoCharts() {
  Hierarchy h;
  h.params.depth = 3;
  h.roots.resize(2);
  h.roots[0][kEdgeRight] = {1, kEdgeLeft, true};
  h.roots[1][kEdgeLeft] = {0, kEdgeRight, true};
  h.charts.resize(2);
  return h;
}

CutNode node(uint32_t chart, uint32_t level, uint32_t x, uint32_t y, uint32_t res) {
  CutNode n;
  n.id = {chart, level, x, y};
  n.resLog2 = res;
  return n;
}

TEST(Overlay, ModesByName) {
  for (OverlayMode m :
       {OverlayMode::kNone, OverlayMode::kChart, OverlayMode::kLevel, OverlayMode::kResolution, OverlayMode::kError})
    EXPECT_EQ(parseOverlayMode(overlayModeName(m)), m);
  EXPECT_EQ(parseOverlayMode("custom"), std::nullopt);
  EXPECT_EQ(parseOverlayMode("charts"), std::nullopt);
  EXPECT_EQ(parseOverlayMode(""), std::nullopt);
}

TEST(Overlay, ChartColoursAreOpaqueAndTellNeighboursApart) {
  std::set<uint32_t> colours;
  for (uint32_t c = 0; c < 256; ++c) {
    const uint32_t rgba = chartColour(c);
    EXPECT_EQ(rgba >> 24, 255u);
    colours.insert(rgba);
    // Consecutive ids (often neighbouring charts) differ clearly in some channel.
    const uint32_t next = chartColour(c + 1);
    int most = 0;
    for (int k = 0; k < 3; ++k)
      most = std::max(most, std::abs(int((rgba >> (8 * k)) & 255) - int((next >> (8 * k)) & 255)));
    EXPECT_GT(most, 40) << "charts " << c << " and " << c + 1;
  }
  EXPECT_GT(colours.size(), 240u);
}

TEST(Overlay, BorderAndOpenSidesFollowTheNodesPlaceInItsChart) {
  const Hierarchy h = twoCharts();
  Cut cut;
  cut.nodes = {node(0, 0, 0, 0, 4),   // a root: all four sides on the border; right shared
               node(0, 1, 1, 0, 3),   // level 1, bottom-right quarter: bottom and right
               node(1, 2, 1, 1, 2),   // level 2, inside: no border side
               node(1, 2, 0, 3, 2)};  // level 2, top-left corner: top and left (shared)
  const std::vector<NodeOverlay> o = nodeOverlays(h, cut, OverlayMode::kChart);
  ASSERT_EQ(o.size(), 4u);
  EXPECT_EQ(o[0].chartBorderSides, 0b1111u);
  EXPECT_EQ(o[0].openSides, 0b1101u);  // bottom, top, left open; right joins chart 1
  EXPECT_EQ(o[1].chartBorderSides, 0b0011u);
  EXPECT_EQ(o[1].openSides, 0b0001u);
  EXPECT_EQ(o[2].chartBorderSides, 0u);
  EXPECT_EQ(o[2].openSides, 0u);
  EXPECT_EQ(o[3].chartBorderSides, 0b1100u);
  EXPECT_EQ(o[3].openSides, 0b0100u);  // top open; left joins chart 0
  EXPECT_EQ(o[0].rgba, o[1].rgba);     // same chart, same colour
  EXPECT_NE(o[0].rgba, o[2].rgba);
  EXPECT_EQ(o[2].rgba, o[3].rgba);

  const std::vector<NodeOverlay> byLevel = nodeOverlays(h, cut, OverlayMode::kLevel);
  EXPECT_NE(byLevel[0].rgba, byLevel[1].rgba);
  EXPECT_EQ(byLevel[2].rgba, byLevel[3].rgba);
  const std::vector<NodeOverlay> byRes = nodeOverlays(h, cut, OverlayMode::kResolution);
  EXPECT_NE(byRes[0].rgba, byRes[1].rgba);
  EXPECT_EQ(byRes[2].rgba, byRes[3].rgba);
  EXPECT_EQ(byRes[0].chartBorderSides, o[0].chartBorderSides);
  EXPECT_TRUE(nodeOverlays(h, cut, OverlayMode::kNone).empty());
  // Custom colours come from the caller, node by node; none given is an error.
  const std::vector<NodeOverlay> custom =
      nodeOverlays(h, cut, OverlayMode::kCustom, [](const NodeId& id) { return 0xFF000000u | id.level; });
  for (size_t i = 0; i < cut.nodes.size(); ++i) EXPECT_EQ(custom[i].rgba, 0xFF000000u | cut.nodes[i].id.level);
  EXPECT_EQ(custom[3].openSides, o[3].openSides);
  EXPECT_THROW(nodeOverlays(h, cut, OverlayMode::kCustom), std::invalid_argument);
}

// The error colouring: each node's screen-space error over the scale on the heat ramp (blue 0,
// green half, red at or above the scale); no scale takes the cut's largest error.
TEST(Overlay, ErrorColouringIsAHeatMapAgainstTheTolerance) {
  const Hierarchy h = twoCharts();
  Cut cut;
  cut.nodes = {node(0, 0, 0, 0, 4), node(0, 1, 1, 0, 3), node(1, 2, 1, 1, 2), node(1, 2, 0, 3, 2)};
  const float errors[4] = {0.f, 0.5f, 1.f, 3.f};
  for (size_t i = 0; i < 4; ++i) cut.nodes[i].errorPx = errors[i];
  const auto rgb = [](uint32_t c) {
    return std::array<int, 3>{int(c & 255), int((c >> 8) & 255), int((c >> 16) & 255)};
  };
  const std::vector<NodeOverlay> o = nodeOverlays(h, cut, OverlayMode::kError, {}, 1.0);
  ASSERT_EQ(o.size(), 4u);
  EXPECT_EQ(rgb(o[0].rgba), (std::array<int, 3>{0, 0, 255}));  // no error: blue
  EXPECT_EQ(rgb(o[1].rgba), (std::array<int, 3>{0, 255, 0}));  // half the tolerance: green
  EXPECT_EQ(rgb(o[2].rgba), (std::array<int, 3>{255, 0, 0}));  // at the tolerance: red
  EXPECT_EQ(o[3].rgba, o[2].rgba);                             // above it: red too
  for (const NodeOverlay& n : o) EXPECT_EQ(n.rgba >> 24, 255u);
  EXPECT_EQ(o[3].chartBorderSides, 0b1100u);
  // Without a scale, the largest error (3 px) is red and 1.5 px would be green.
  const std::vector<NodeOverlay> own = nodeOverlays(h, cut, OverlayMode::kError);
  EXPECT_EQ(rgb(own[3].rgba), (std::array<int, 3>{255, 0, 0}));
  EXPECT_EQ(rgb(own[0].rgba), (std::array<int, 3>{0, 0, 255}));
  EXPECT_NE(own[2].rgba, o[2].rgba);
  EXPECT_EQ(heatColour(-1.0), heatColour(0.0));
  EXPECT_EQ(heatColour(2.0), heatColour(1.0));
}

}  // namespace
}  // namespace gimlod
