#include "inspect/report.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <numeric>
#include <sstream>

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include "core/atlas_format.h"
#include "inspect/hierarchy_report.h"
#include "inspect/png.h"
#include "inspect/seams.h"
#include "inspect/source_report.h"
#include "runtime/atlas_view.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr const char* kReportMarker = "report.json";

bool isObject(const json& j, const char* key) { return j.contains(key) && j[key].is_object(); }

uint8_t unit(double x) { return uint8_t(std::lround(std::clamp(x, 0.0, 1.0) * 255.0)); }

// The colour of stretch s (1: none): the heat ramp over log2 s in [0, 2] (1 blue, 2 green, 4 red).
std::array<uint8_t, 3> heat(double stretch) { return heatColour(std::log2(std::max(stretch, 1.0)) / 2.0); }

std::string html(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '&': o += "&amp;"; break;
      case '"': o += "&quot;"; break;
      default: o += c;
    }
  }
  return o;
}

std::string number(const json& v) {
  if (v.is_number_float()) {
    std::ostringstream s;
    s.precision(4);
    s << v.get<double>();
    return s.str();
  }
  return v.is_string() ? html(v.get<std::string>()) : html(v.dump());
}

uint64_t directoryBytes(const fs::path& dir) {
  uint64_t bytes = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) bytes += e.file_size();
  return bytes;
}

// The images of one chart at the pyramid level whose side is at most maxSide samples.
struct ChartImages {
  json figures;
  std::vector<std::string> files;
};

ChartImages chartImages(const AtlasManifest& m, const fs::path& atlasDir, uint32_t chart, uint32_t maxSide,
                        const fs::path& outDir, const std::array<float, 6>& bounds) {
  const ChartFileReader r(atlasDir / m.charts[chart].file);
  // Levels of the chart file (its level 0 is the chart's finest, ChartInfo::finestLevel).
  const uint32_t size = m.chartFileSize(chart);
  uint32_t level = 0;
  while (level + 1 < r.levels() && ((size - 1) >> level) + 1 > maxSide) ++level;
  const uint32_t n = ((size - 1) >> level) + 1;
  ChartImages out;
  const std::vector<PackedNormal> normals = r.readLevelNormals(level);
  std::vector<uint8_t> rgb(size_t(n) * n * 3);
  // Images are drawn with v up (row 0 of the PNG is v = n - 1).
  auto at = [&](uint32_t u, uint32_t v) { return (size_t(n - 1 - v) * n + u) * 3; };
  for (uint32_t v = 0; v < n; ++v)
    for (uint32_t u = 0; u < n; ++u) {
      const PackedNormal& p = normals[size_t(v) * n + u];
      for (int c = 0; c < 3; ++c) rgb[at(u, v) + c] = p[c];
    }
  const std::string stem = "chart_" + std::to_string(chart);
  writePngRgb(outDir / (stem + "_normals.png"), n, n, rgb);
  out.files.push_back(stem + "_normals.png");
  out.figures["image_level"] = level + m.charts[chart].finestLevel;
  out.figures["finest_level"] = m.charts[chart].finestLevel;
  if (m.kind == AtlasKind::Geometry) {
    const std::vector<glm::vec3> pos = r.readLevelPositions(level);
    for (uint32_t v = 0; v < n; ++v)
      for (uint32_t u = 0; u < n; ++u)
        for (int c = 0; c < 3; ++c) {
          const double lo = bounds[c], hi = bounds[c + 3];
          rgb[at(u, v) + c] = unit(hi > lo ? (pos[size_t(v) * n + u][c] - lo) / (hi - lo) : 0.5);
        }
    writePngRgb(outDir / (stem + "_positions.png"), n, n, rgb);
    out.files.push_back(stem + "_positions.png");
    // Stretch per texel: the root mean square of its two edge lengths against the chart's mean,
    // so 1 is even sampling; texels facing against their vertex normals in magenta.
    std::vector<double> len((n - 1) * size_t(n - 1));
    double sum = 0.0;
    uint32_t backwards = 0, degenerate = 0;
    for (uint32_t v = 0; v + 1 < n; ++v)
      for (uint32_t u = 0; u + 1 < n; ++u) {
        const size_t i = size_t(v) * n + u;
        const glm::dvec3 du = glm::dvec3(pos[i + 1]) - glm::dvec3(pos[i]);
        const glm::dvec3 dv = glm::dvec3(pos[i + n]) - glm::dvec3(pos[i]);
        len[size_t(v) * (n - 1) + u] = std::sqrt(0.5 * (glm::dot(du, du) + glm::dot(dv, dv)));
        sum += len[size_t(v) * (n - 1) + u];
      }
    const double mean = sum / double(len.size());
    double worst = 0.0;
    std::vector<uint8_t> heatRgb(size_t(n - 1) * (n - 1) * 3);
    for (uint32_t v = 0; v + 1 < n; ++v)
      for (uint32_t u = 0; u + 1 < n; ++u) {
        const size_t i = size_t(v) * n + u;
        const double s = mean > 0.0 ? len[size_t(v) * (n - 1) + u] / mean : 1.0;
        worst = std::max(worst, s);
        std::array<uint8_t, 3> c =
            heat(std::max(s, mean > 0.0 ? mean / std::max(len[size_t(v) * (n - 1) + u], 1e-30) : 1.0));
        const glm::dvec3 d1 = glm::dvec3(pos[i + n + 1]) - glm::dvec3(pos[i]);
        const glm::dvec3 d2 = glm::dvec3(pos[i + n]) - glm::dvec3(pos[i + 1]);
        glm::dvec3 nsum(0.0);
        for (const size_t k : {i, i + 1, i + n, i + n + 1}) {
          const std::array<float, 3> un = unpackNormal(normals[k]);
          nsum += glm::dvec3(un[0], un[1], un[2]);
        }
        const glm::dvec3 cr = glm::cross(d1, d2);
        if (!(glm::length(cr) > 1e-8 * (glm::dot(d1, d1) + glm::dot(d2, d2)))) {
          c = {255, 255, 255};  // (near) zero area: a degenerate texel
          ++degenerate;
        } else if (glm::dot(cr, nsum) < 0.0) {
          c = {255, 0, 255};
          ++backwards;
        }
        const size_t o = (size_t(n - 2 - v) * (n - 1) + u) * 3;
        heatRgb[o] = c[0], heatRgb[o + 1] = c[1], heatRgb[o + 2] = c[2];
      }
    writePngRgb(outDir / (stem + "_stretch.png"), n - 1, n - 1, heatRgb);
    out.files.push_back(stem + "_stretch.png");
    out.figures["texel_stretch_max"] = worst;
    out.figures["texels_against_normals_at_image_level"] = backwards;
    out.figures["degenerate_texels_at_image_level"] = degenerate;
  } else {
    const std::vector<float> h = r.readLevelHeights(level);
    const auto [lo, hi] = std::minmax_element(h.begin(), h.end());
    for (uint32_t v = 0; v < n; ++v)
      for (uint32_t u = 0; u < n; ++u) {
        const uint8_t g = unit(*hi > *lo ? (h[size_t(v) * n + u] - *lo) / (*hi - *lo) : 0.5);
        rgb[at(u, v)] = rgb[at(u, v) + 1] = rgb[at(u, v) + 2] = g;
      }
    writePngRgb(outDir / (stem + "_heights.png"), n, n, rgb);
    out.files.push_back(stem + "_heights.png");
  }
  return out;
}

// Every chart's figures, the worst first: from the build's per-chart quality (geometry), or the
// height range of each chart (height fields).
json chartTable(const AtlasManifest& m, const fs::path& atlasDir, const json& stats) {
  json rows = json::array();
  const json* perChart = isObject(stats, "resample") && stats["resample"].contains("per_chart") &&
                                 stats["resample"]["per_chart"].is_array()
                             ? &stats["resample"]["per_chart"]
                             : nullptr;
  for (uint32_t c = 0; c < m.charts.size(); ++c) {
    json row = {{"chart", c}, {"file", m.charts[c].file}};
    int open = 0;
    for (const RootNeighbour& nb : m.charts[c].neighbours) open += nb.chart < 0;
    row["open_edges"] = open;
    if (perChart && c < perChart->size()) {
      for (const auto& [k, v] : (*perChart)[c].items()) row[k] = v;
    } else if (m.kind == AtlasKind::Heightfield) {
      const ChartFileReader r(atlasDir / m.charts[c].file);
      const std::vector<float> h = r.readLevelHeights(r.levels() - 1);
      const auto [lo, hi] = std::minmax_element(h.begin(), h.end());
      row["grid_x"] = m.charts[c].gridX;
      row["grid_y"] = m.charts[c].gridY;
      row["height_min"] = *lo;
      row["height_max"] = *hi;
    }
    rows.push_back(row);
  }
  const auto key = [](const json& r) {
    const auto get = [&](const char* k) { return r.contains(k) ? r[k].get<double>() : 0.0; };
    return std::make_tuple(get("flipped_texels"), get("degenerate_texels"), get("stretch_linf"),
                           get("height_max") - get("height_min"));
  };
  std::stable_sort(rows.begin(), rows.end(), [&](const json& a, const json& b) { return key(a) > key(b); });
  return rows;
}

json seamJson(const SeamReport& s) {
  json levels = json::array(), offenders = json::array(), valence = json::object();
  for (const SeamLevel& l : s.levels)
    levels.push_back({{"level", l.level},
                      {"edge_samples", l.edgeSamples},
                      {"edge_mismatches", l.edgeMismatches},
                      {"max_edge_difference", l.maxEdgeDifference},
                      {"corner_samples", l.cornerSamples},
                      {"corner_mismatches", l.cornerMismatches},
                      {"max_corner_difference", l.maxCornerDifference}});
  for (const SeamOffender& o : s.offenders)
    offenders.push_back({{"level", o.level},
                         {"chart", o.chart},
                         {"edge", o.edge},
                         {"sample", o.sample},
                         {"other_chart", o.otherChart},
                         {"other_edge", o.otherEdge},
                         {"other_sample", o.otherSample},
                         {"corner", o.corner},
                         {"difference", o.difference}});
  for (const auto& [charts, corners] : s.cornerValence) valence[std::to_string(charts)] = corners;
  return {{"seamless", s.seamless()},
          {"mismatches", s.mismatches()},
          {"max_difference", s.maxDifference()},
          {"shared_edges", s.sharedEdges},
          {"open_edges", s.openEdges},
          {"corner_valence", valence},
          {"levels", levels},
          {"offenders", offenders},
          {"seconds", s.seconds}};
}

// The hierarchy: per level, the largest error against resolution as an SVG chart (log scale),
// the figures as a table, and each level's heat map.
std::string errorCurveHtml(const json& hr) {
  std::ostringstream h;
  h << "<h2>Hierarchy</h2>\n";
  double lo = std::numeric_limits<double>::infinity(), hi = 0.0;
  uint32_t resLo = 64, resHi = 0;
  for (const json& l : hr["levels"])
    for (const json& e : l["errors"]) {
      const double v = e["max_error"].get<double>();
      if (v > 0.0) lo = std::min(lo, v), hi = std::max(hi, v);
      resLo = std::min(resLo, e["res"].get<uint32_t>()), resHi = std::max(resHi, e["res"].get<uint32_t>());
    }
  if (hi > 0.0 && resHi > resLo) {
    const double W = 480, H = 240, pad = 40;
    const double l0 = std::floor(std::log10(lo)), l1 = std::ceil(std::log10(hi)) + (lo == hi ? 1 : 0);
    const auto X = [&](double res) { return pad + (res - resLo) / double(resHi - resLo) * (W - 2 * pad); };
    const auto Y = [&](double v) { return H - pad - (std::log10(v) - l0) / (l1 - l0) * (H - 2 * pad); };
    h << "<svg id=\"error-curve\" width=\"" << W << "\" height=\"" << H << "\" xmlns=\"http://www.w3.org/2000/svg\" "
      << "style=\"border:1px solid #bbb\"><text x=\"" << W / 2 << "\" y=\"" << H - 8
      << "\" text-anchor=\"middle\" font-size=\"12\">resolution (log2 intervals)</text>"
      << "<text x=\"12\" y=\"" << H / 2 << "\" font-size=\"12\" transform=\"rotate(-90 12 " << H / 2
      << ")\" text-anchor=\"middle\">largest error (log)</text>";
    for (double d = l0; d <= l1; d += 1.0)
      h << "<line x1=\"" << pad << "\" x2=\"" << W - pad << "\" y1=\"" << Y(std::pow(10.0, d)) << "\" y2=\""
        << Y(std::pow(10.0, d)) << "\" stroke=\"#ddd\"/><text x=\"" << W - pad + 2 << "\" y=\""
        << Y(std::pow(10.0, d)) + 4 << "\" font-size=\"10\">1e" << int(d) << "</text>";
    static const char* kColours[] = {"#4477aa", "#228833", "#ccbb44", "#ee6677",
                                     "#aa3377", "#66ccee", "#bbbbbb", "#000000"};
    for (const json& l : hr["levels"]) {
      std::ostringstream pts;
      for (const json& e : l["errors"])
        if (e["max_error"].get<double>() > 0.0)
          pts << X(e["res"].get<double>()) << "," << Y(e["max_error"].get<double>()) << " ";
      const uint32_t level = l["level"].get<uint32_t>();
      h << "<polyline fill=\"none\" stroke-width=\"2\" stroke=\"" << kColours[level % 8] << "\" points=\"" << pts.str()
        << "\"><title>level " << level << "</title></polyline>";
    }
    h << "</svg>\n";
  }
  h << "<table id=\"hierarchy\"><tr><th>level</th><th>nodes</th><th>resolution: largest / mean error</th></tr>";
  for (const json& l : hr["levels"]) {
    h << "<tr><td>" << l["level"] << "</td><td>" << l["nodes"] << "</td><td>";
    for (const json& e : l["errors"])
      h << e["res"] << ": " << number(e["max_error"]) << " / " << number(e["mean_error"]) << "&emsp;";
    h << "</td></tr>";
  }
  h << "</table>\n<p>Heat maps: each node's error at each resolution it may use (blue: 10<sup>-4</sup> of the "
       "largest error or less, red: the largest), charts tiled in a grid (a DEM's at their place).</p>\n";
  for (const json& l : hr["levels"]) {
    if (l["heat_maps"].empty()) continue;
    h << "<div class=\"level\">";
    for (const json& m : l["heat_maps"])
      h << "<figure><img src=\"" << html(m["file"].get<std::string>()) << "\" alt=\"level " << l["level"] << " res "
        << m["res"] << " errors\"><figcaption>level " << l["level"] << ", resolution " << m["res"]
        << "</figcaption></figure>";
    h << "</div>\n";
  }
  return h.str();
}

std::string sourceHtml(const json& s) {
  std::ostringstream h;
  h << "<h2>Source comparison</h2>\n<p>The atlas (level 0, every chart's grid as drawn) against "
    << html(s["source"].get<std::string>()) << ", two-sided, sample by sample.</p>\n<table id=\"source\">";
  for (const char* k :
       {"hausdorff_percent_of_diagonal", "mean_percent_of_diagonal", "hausdorff", "max_atlas_to_mesh",
        "max_mesh_to_atlas", "diagonal", "atlas_samples", "mesh_samples", "max_vertical_distance",
        "mean_vertical_distance", "height_range", "samples_compared", "voids_filled_in_source", "seconds"})
    if (s.contains(k))
      h << "<tr><td>" << k << "</td><td data-key=\"source_" << k << "\">" << number(s[k]) << "</td></tr>";
  h << "</table>\n<table id=\"source-worst-atlas\"><tr><th>atlas sample: chart</th><th>u</th><th>v</th><th>position "
       "(a DEM: its sample)</th>"
       "<th>distance to the input</th></tr>";
  for (const json& w : s["worst_atlas_samples"])
    h << "<tr><td>" << w["chart"] << "</td><td>" << w["u"] << "</td><td>" << w["v"] << "</td><td>"
      << number(w.contains("position") ? w["position"] : json::array({w["gx"], w["gy"]})) << "</td><td>"
      << number(w["distance"]) << "</td></tr>";
  h << "</table>\n<table id=\"source-worst-input\"><tr><th>input sample</th><th>position</th><th>distance to the "
       "atlas</th><th>nearest chart</th><th>u</th><th>v</th></tr>";
  for (const json& w : s["worst_input_samples"])
    h << "<tr><td>" << w["sample"] << "</td><td>" << number(w["position"]) << "</td><td>" << number(w["distance"])
      << "</td><td>" << w["chart"] << "</td><td>" << w["u"] << "</td><td>" << w["v"] << "</td></tr>";
  h << "</table>\n<p>Distance of every sample of the farthest charts (blue: 10<sup>-4</sup> of the atlas's largest "
       "distance or less, red: the largest).</p>\n";
  for (const json& m : s["distance_maps"])
    h << "<figure><img src=\"" << html(m["file"].get<std::string>()) << "\" alt=\"chart " << m["chart"]
      << " distances\"><figcaption>chart " << m["chart"] << ": " << number(m["max_distance"])
      << "</figcaption></figure>";
  h << "\n";
  return h.str();
}

std::string streamingHtml(const json& s) {
  std::ostringstream h;
  h << "<h2>Memory and streaming</h2>\n<table id=\"pyramid-bytes\"><tr><th>pyramid level</th><th>samples a side</th>"
       "<th>bytes</th></tr>";
  for (const json& l : s["pyramid_levels"])
    h << "<tr><td>" << l["pyramid_level"] << "</td><td>" << l["samples_per_side"] << "</td><td>" << l["bytes"]
      << "</td></tr>";
  h << "</table>\n<table id=\"pages\"><tr><th>node level</th><th>page samples a side</th><th>page bytes</th></tr>";
  for (const json& l : s["pages"])
    h << "<tr><td>" << l["level"] << "</td><td>" << l["page_samples_per_side"] << "</td><td>" << l["page_bytes"]
      << "</td></tr>";
  h << "</table>\n<p>The six axis views at " << html(s["view_size"].get<std::string>())
    << ", 1-pixel tolerance, no node budget:</p>\n<table id=\"view-needs\"><tr><th>view</th><th>nodes (pages)</th>"
       "<th>triangles</th><th>page bytes</th><th>stitching raises</th><th>stitching splits</th><th>nodes drawn finer "
       "than "
       "their error needs</th></tr>";
  for (const json& v : s["views"])
    h << "<tr><td>" << html(v["view"].get<std::string>()) << "</td><td>" << v["nodes"] << "</td><td>" << v["triangles"]
      << "</td><td>" << v["page_bytes"] << "</td><td>" << v["constraint_raises"] << "</td><td>"
      << v["constraint_splits"] << "</td><td>" << v["nodes_raised"] << "</td></tr>";
  h << "</table>\n";
  for (const json& v : s["views"]) {
    if (v["raised"].empty()) continue;
    h << "<p>Nodes the stitching constraint raised in the view from " << html(v["view"].get<std::string>())
      << " (the first " << v["raised"].size()
      << "):</p>\n<table id=\"raised\"><tr><th>chart</th><th>level</th>"
         "<th>x</th><th>y</th><th>resolution its error needs</th><th>drawn</th></tr>";
    for (const json& n : v["raised"])
      h << "<tr><td>" << n["chart"] << "</td><td>" << n["level"] << "</td><td>" << n["x"] << "</td><td>" << n["y"]
        << "</td><td>" << n["needed_res"] << "</td><td>" << n["drawn_res"] << "</td></tr>";
    h << "</table>\n";
    break;
  }
  return h.str();
}

std::string pageHtml(const json& r) {
  std::ostringstream h;
  const json& sum = r["summary"];
  h << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>gimlod inspect: "
    << html(sum["atlas"].get<std::string>()) << "</title>\n<style>\n"
    << "body{font-family:sans-serif;margin:1.5em;color:#222}table{border-collapse:collapse;margin:.5em 0 1.5em}"
    << "td,th{border:1px solid #bbb;padding:2px 8px;text-align:right}th{background:#eee;cursor:pointer}"
    << "td:first-child,th:first-child{text-align:left}.bad{background:#fcc}.ok{background:#cfc}"
    << "figure{display:inline-block;margin:4px;text-align:center}figure img{width:160px;image-rendering:pixelated}"
    << "figure.view{width:324px;vertical-align:top}.view img{width:320px}figcaption{font-size:12px}"
    << "</style></head>\n<body>\n";
  h << "<h1>Atlas " << html(sum["atlas"].get<std::string>()) << "</h1>\n<h2>Summary</h2>\n<table id=\"summary\">";
  for (const auto& [k, v] : sum.items())
    h << "<tr><td>" << html(k) << "</td><td data-key=\"" << html(k) << "\">" << number(v) << "</td></tr>";
  h << "</table>\n";
  if (r.contains("stages") && r["stages"].is_array() && !r["stages"].empty()) {
    h << "<h2>Build stages</h2>\n<table id=\"stages\"><tr><th>stage</th><th>seconds</th><th>CPU seconds</th><th>peak "
         "RSS "
         "(bytes)</th></tr>";
    for (const json& st : r["stages"])
      h << "<tr><td>" << number(st.value("stage", json(""))) << "</td><td>" << number(st.value("seconds", json(0.0)))
        << "</td><td>" << number(st.value("cpu_seconds", json(0.0))) << "</td><td>"
        << number(st.value("peak_rss_bytes", json(0))) << "</td></tr>";
    h << "</table>\n";
  }
  if (!r["views"].empty()) {
    h << "<h2>Views</h2>\n";
    for (const json& v : r["views"])
      h << "<figure class=\"view\"><img src=\"" << html(v["file"].get<std::string>()) << "\" alt=\""
        << html(v["caption"].get<std::string>()) << "\"><figcaption>" << html(v["caption"].get<std::string>())
        << "</figcaption></figure>";
  }
  bool crackTable = false;
  for (const json& v : r["views"]) crackTable = crackTable || v.contains("other_boundary_edges");
  if (crackTable) {
    h << "<h2>Cracks</h2>\n<p>Each view's cut as drawn: the stitched positions captured from the vertex shader, "
         "welded where bit-identical (gimlod render --export-cut). Boundary edges on open chart borders are the "
         "input's own; any other is a crack.</p>\n<table id=\"cracks\"><tr><th>view</th><th>nodes</th><th>boundary "
         "edges</th><th>on open chart borders</th><th>cracks</th></tr>";
    for (const json& v : r["views"]) {
      if (!v.contains("other_boundary_edges")) continue;
      h << "<tr" << (v["other_boundary_edges"].get<uint64_t>() ? " class=\"bad\"" : "") << "><td>"
        << html(v.value("view", v["file"].get<std::string>())) << "</td><td>" << v.value("nodes", 0) << "</td><td>"
        << v["boundary_edges"] << "</td><td>" << v["open_border_edges"] << "</td><td>" << v["other_boundary_edges"]
        << "</td></tr>";
    }
    h << "</table>\n";
  }
  const json& seams = r["seams"];
  h << "<h2>Seams</h2>\n<p id=\"seam-verdict\" class=\"" << (seams["seamless"].get<bool>() ? "ok" : "bad") << "\">"
    << (seams["seamless"].get<bool>() ? "Every shared edge and corner is bit-identical at every level."
                                      : std::to_string(seams["mismatches"].get<uint64_t>()) +
                                            " shared samples differ; the largest offenders are listed below.")
    << "</p>\n<table id=\"seams\"><tr><th>level</th><th>edge samples</th><th>edge mismatches</th><th>max edge "
       "difference</th><th>corner samples</th><th>corner mismatches</th><th>max corner difference</th></tr>";
  for (const json& l : seams["levels"])
    h << "<tr"
      << (l["edge_mismatches"].get<uint64_t>() + l["corner_mismatches"].get<uint64_t>() ? " class=\"bad\"" : "")
      << "><td>" << l["level"] << "</td><td>" << l["edge_samples"] << "</td><td>" << l["edge_mismatches"] << "</td><td>"
      << number(l["max_edge_difference"]) << "</td><td>" << l["corner_samples"] << "</td><td>" << l["corner_mismatches"]
      << "</td><td>" << number(l["max_corner_difference"]) << "</td></tr>";
  h << "</table>\n";
  if (!seams["offenders"].empty()) {
    h << "<table id=\"seam-offenders\"><tr><th>level</th><th>chart</th><th>edge</th><th>sample</th><th>other "
         "chart</th><th>other edge</th><th>other sample</th><th>corner</th><th>difference</th></tr>";
    for (const json& o : seams["offenders"])
      h << "<tr><td>" << o["level"] << "</td><td>" << o["chart"] << "</td><td>" << o["edge"] << "</td><td>"
        << o["sample"] << "</td><td>" << o["other_chart"] << "</td><td>" << o["other_edge"] << "</td><td>"
        << o["other_sample"] << "</td><td>" << o["corner"] << "</td><td>" << number(o["difference"]) << "</td></tr>";
    h << "</table>\n";
  }
  if (r.contains("source")) h << sourceHtml(r["source"]);
  h << errorCurveHtml(r["hierarchy"]);
  h << streamingHtml(r["streaming"]);
  h << "<h2>Worst charts</h2>\n";
  for (const json& c : r["chart_images"]) {
    h << "<div class=\"chart\" id=\"chart-" << c["chart"] << "\"><h3>Chart " << c["chart"] << "</h3>";
    for (const json& f : c["files"])
      h << "<figure><img src=\"" << html(f.get<std::string>()) << "\" alt=\"" << html(f.get<std::string>())
        << "\"><figcaption>" << html(f.get<std::string>()) << "</figcaption></figure>";
    h << "</div>\n";
  }
  h << "<h2>Charts</h2>\n<p>Click a heading to sort.</p>\n<table id=\"charts\"><thead><tr>";
  std::vector<std::string> cols;
  for (const json& row : r["charts"])
    for (const auto& [k, v] : row.items())
      if (std::find(cols.begin(), cols.end(), k) == cols.end()) cols.push_back(k);
  for (const std::string& c : cols) h << "<th>" << html(c) << "</th>";
  h << "</tr></thead><tbody>";
  for (const json& row : r["charts"]) {
    h << "<tr>";
    for (const std::string& c : cols) h << "<td>" << (row.contains(c) ? number(row[c]) : "") << "</td>";
    h << "</tr>";
  }
  h << "</tbody></table>\n<script>\n"
    << "document.querySelectorAll('#charts th').forEach((th, i) => th.addEventListener('click', () => {\n"
    << "  const body = document.querySelector('#charts tbody');\n"
    << "  const rows = Array.from(body.rows), down = th.dataset.down !== '1';\n"
    << "  const val = r => { const t = r.cells[i].textContent, n = parseFloat(t); return isNaN(n) ? t : n; };\n"
    << "  rows.sort((a, b) => (val(a) > val(b) ? 1 : val(a) < val(b) ? -1 : 0) * (down ? -1 : 1));\n"
    << "  th.dataset.down = down ? '1' : '0'; rows.forEach(r => body.appendChild(r));\n"
    << "}));\n"
    << "window.addEventListener('load', () => {\n"
    << "  const imgs = Array.from(document.images);\n"
    << "  document.body.dataset.images = imgs.length;\n"
    << "  document.body.dataset.brokenImages = imgs.filter(i => !i.complete || i.naturalWidth === 0).length;\n"
    << "});\n</script>\n</body></html>\n";
  return h.str();
}

}  // namespace

namespace {
InspectResult writeReport(const InspectOptions& o, const AtlasManifest& m, const json& stats);
}  // namespace

InspectResult writeInspectReport(const InspectOptions& o) {
  if (o.worstCharts > 10000) throw InputError(optionRef("worstCharts") + " must be at most 10000");
  if (o.thumbnailSize < 3 || o.thumbnailSize > 1025)
    throw InputError(optionRef("thumbnailSize") + " must be in [3, 1025]");
  const AtlasManifest m = readManifest(o.atlas);
  json stats = json::object();
  const fs::path statsFile = o.atlas / "stats.json";
  if (fs::exists(statsFile)) {
    std::ifstream in(statsFile);
    try {
      stats = json::parse(in);
    } catch (const json::exception& e) {
      throw InputError(statsFile.string() + ": not valid JSON (" + e.what() + ")");
    }
    if (!stats.is_object()) throw InputError(statsFile.string() + ": not a JSON object");
  }
  try {
    return writeReport(o, m, stats);
  } catch (const json::exception& e) {
    // A figure of stats.json of an unexpected type (the file was edited or damaged).
    throw InputError(statsFile.string() + ": unexpected content (" + e.what() + ")");
  }
}

namespace {

InspectResult writeReport(const InspectOptions& o, const AtlasManifest& m, const json& stats) {
  const auto t0 = std::chrono::steady_clock::now();
  StagedDirectory staged(o.output, kReportMarker, "report");
  const fs::path dir = staged.path();

  json report;
  uint64_t samples = 0;  // the charts' finest samples (ChartInfo::finestLevel)
  for (const ChartInfo& c : m.charts) samples += uint64_t(m.chartFileSize(c.id)) * m.chartFileSize(c.id);
  const uint64_t bytes = directoryBytes(o.atlas);
  uint64_t nodes = 0;
  for (uint32_t l = 0; l < m.depth; ++l) nodes += uint64_t(m.charts.size()) << (2 * l);
  json& sum = report["summary"];
  sum["atlas"] = fs::absolute(o.atlas).lexically_normal().string();
  sum["kind"] = atlasKindName(m.kind);
  sum["charts"] = m.charts.size();
  if (isObject(stats, "resample") && isObject(stats, "charting"))
    sum["patches"] = stats["resample"].value("patches", stats["charting"].value("patches", 0));
  sum["chart_size"] = m.chartSize;
  sum["samples"] = samples;
  sum["bytes_on_disk"] = bytes;
  sum["bytes_per_sample"] = double(bytes) / double(std::max<uint64_t>(samples, 1));
  if (isObject(stats, "read") && stats["read"].contains("triangles") && stats["read"]["triangles"].is_number())
    sum["bytes_per_input_triangle"] = double(bytes) / std::max(1.0, stats["read"]["triangles"].get<double>());
  sum["hierarchy_depth"] = m.depth;
  sum["hierarchy_nodes"] = nodes;
  if (m.kind == AtlasKind::Geometry) {
    // Charts by the level their pyramid starts at (ChartInfo::finestLevel; 0: the chart size).
    std::vector<uint32_t> byLevel;
    for (const ChartInfo& c : m.charts) {
      if (byLevel.size() <= c.finestLevel) byLevel.resize(c.finestLevel + 1, 0);
      ++byLevel[c.finestLevel];
    }
    sum["charts_by_finest_level"] = byLevel;
  }
  if (stats.contains("total_seconds")) sum["build_seconds"] = stats["total_seconds"];
  if (stats.contains("peak_rss_bytes")) sum["build_peak_rss_bytes"] = stats["peak_rss_bytes"];
  if (isObject(stats, "resample")) {
    const json& rs = stats["resample"];
    for (const char* k : {"image_stretch_l2", "image_stretch_linf", "flipped_texels", "degenerate_texels"})
      if (rs.contains(k)) sum[k] = rs[k];
  }
  if (stats.contains("fidelity")) {
    const json& f = stats["fidelity"];
    if (f.is_object()) {
      sum["hausdorff_percent_of_diagonal"] = f.value("hausdorff_percent_of_diagonal", json());
      sum["hausdorff_mean_percent_of_diagonal"] = f.value("mean_percent_of_diagonal", json());
    } else {
      sum["hausdorff_percent_of_diagonal"] = f;  // e.g. "not measured (--no-fidelity)"
    }
  }
  if (stats.contains("voids_filled")) sum["voids_filled"] = stats["voids_filled"];
  if (stats.contains("stages")) report["stages"] = stats["stages"];

  const SeamReport seams = validateSeams(o.atlas);
  report["seams"] = seamJson(seams);
  sum["seams_bit_identical"] = seams.seamless();
  sum["seam_mismatches"] = seams.mismatches();

  const AtlasView view = openAtlas(o.atlas);
  // The roots of the forest: the top groups above the charts (hierarchy/root_groups.h), or the
  // charts where there are none; the smallest cut of a view that takes in the whole atlas.
  const RootGroups& groups = view.hierarchy.groups;
  sum["groups"] = groups.groups.size();
  sum["roots"] = groups.empty() ? m.charts.size() : groups.tops.size();
  report["hierarchy"] = hierarchyFigures(view, dir);
  report["streaming"] = streamingFigures(view);
  sum["view_nodes_mean"] = report["streaming"]["view_nodes_mean"];
  sum["view_page_bytes_mean"] = report["streaming"]["view_page_bytes_mean"];

  SourceDistances distances;
  if (!o.source.empty()) {
    report["source"] = sourceComparison(m, o.atlas, o.source, {dir, 6, 16}, &distances);
    sum["source_hausdorff_percent_of_diagonal"] = report["source"]["hausdorff_percent_of_diagonal"];
    sum["source_mean_percent_of_diagonal"] = report["source"]["mean_percent_of_diagonal"];
  }

  report["charts"] = chartTable(m, o.atlas, stats);
  std::array<float, 6> bounds{0, 0, 0, 1, 1, 1};
  if (stats.contains("bounds") && stats["bounds"].is_array() && stats["bounds"].size() == 6)
    for (int i = 0; i < 6; ++i) bounds[i] = stats["bounds"][i].get<float>();
  InspectResult result;
  result.images += uint32_t(report["hierarchy"]["heat_maps"].size());
  if (report.contains("source")) result.images += uint32_t(report["source"]["distance_maps"].size());
  report["chart_images"] = json::array();
  for (size_t i = 0; i < report["charts"].size() && i < o.worstCharts; ++i) {
    const uint32_t c = report["charts"][i]["chart"].get<uint32_t>();
    ChartImages ci = chartImages(m, o.atlas, c, o.thumbnailSize, dir, bounds);
    result.images += uint32_t(ci.files.size());
    json entry = {{"chart", c}, {"files", ci.files}};
    for (const auto& [k, v] : ci.figures.items()) entry[k] = v;
    report["chart_images"].push_back(entry);
  }
  std::vector<ReportImage> views = o.views;
  if (o.renderViews) {
    std::vector<ReportImage> more = o.renderViews(o.source.empty() ? nullptr : &distances);
    views.insert(views.end(), more.begin(), more.end());
  }
  report["views"] = json::array();
  for (size_t i = 0; i < views.size(); ++i) {
    const std::string name = "view_" + std::to_string(i) + ".png";
    std::error_code ec;
    fs::copy_file(views[i].png, dir / name, ec);
    if (ec) throw InputError(views[i].png.string() + ": cannot copy into the report (" + ec.message() + ")");
    json entry = {{"file", name}, {"caption", views[i].caption}};
    for (const auto& [k, v] : views[i].figures.items()) entry[k] = v;
    if (entry.contains("other_boundary_edges"))
      sum["crack_edges_in_views"] =
          sum.value("crack_edges_in_views", uint64_t(0)) + entry["other_boundary_edges"].get<uint64_t>();
    report["views"].push_back(entry);
    ++result.images;
  }
  report["build"] = stats;
  const std::string text = report.dump(1);
  atomicWriteFile(dir / kReportMarker, text.data(), text.size());
  const std::string page = pageHtml(report);
  atomicWriteFile(dir / "index.html", page.data(), page.size());
  result.bytes = directoryBytes(dir);
  staged.commit();
  result.figures = std::move(report);
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

}  // namespace
}  // namespace gimlod
