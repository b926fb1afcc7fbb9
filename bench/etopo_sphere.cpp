// Turns a global lat/long DEM (e.g. ETOPO5, 4320 x 2161 samples from pole to pole) into a closed
// genus-0 sphere mesh for the large mesh-atlas benchmarks: every interior grid row becomes a ring
// of vertices displaced radially by elevation * exaggeration, and each pole is closed by a single
// vertex. Writes a binary little-endian PLY, streamed (the triangles are never held in memory).
//
//   etopo_sphere DEM -o OUT.ply [--step K] [--exaggeration E] [--radius R]
//
// --step K keeps every K-th column and row (K must divide the column count); the full ETOPO5 grid
// (K = 1) gives 18,653,760 triangles, K = 4 gives 1,164,240. Units are kilometres: radius R
// (default 6371) plus elevation (metres / 1000) * E (default 20).
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "atlas/dem.h"

namespace {

struct SphereGrid {
  uint32_t columns = 0;  // vertices per ring
  uint32_t rings = 0;    // interior rows kept
  uint64_t vertices() const { return uint64_t(columns) * rings + 2; }
  uint64_t triangles() const { return uint64_t(columns) * 2 * (rings - 1) + uint64_t(columns) * 2; }
};

int usage() {
  std::fprintf(stderr, "usage: etopo_sphere DEM -o OUT.ply [--step K] [--exaggeration E] [--radius R]\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::filesystem::path input, output;
  uint32_t step = 1;
  double exaggeration = 20.0, radius = 6371.0;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    try {
      if (a == "-o") output = next();
      else if (a == "--step") step = uint32_t(std::stoul(next()));
      else if (a == "--exaggeration") exaggeration = std::stod(next());
      else if (a == "--radius") radius = std::stod(next());
      else if (!a.empty() && a[0] == '-') return usage();
      else input = a;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "etopo_sphere: %s\n", e.what());
      return usage();
    }
  }
  if (input.empty() || output.empty() || step == 0 || !(radius > 0) || !std::isfinite(exaggeration))
    return usage();
  try {
    const gimlod::DemRaster dem = gimlod::loadDem(input);  // row 0 = south edge
    if (dem.width % step || dem.height < 3 + 2 * step)
      throw std::invalid_argument("--step " + std::to_string(step) + " must divide the width (" +
                                  std::to_string(dem.width) + ") and leave at least one interior row");
    // Rows 0 and height-1 are the poles; the interior rows step..height-1-step are rings.
    std::vector<uint32_t> rows;
    for (uint32_t r = step; r + step <= dem.height - 1; r += step) rows.push_back(r);
    SphereGrid g;
    g.columns = dem.width / step;
    g.rings = uint32_t(rows.size());
    if (g.vertices() > 0x7fffffffull) throw std::invalid_argument("too many vertices for a PLY int index");
    const double kPi = 3.14159265358979323846;
    auto heightAt = [&](uint32_t row, uint32_t col) {
      return double(dem.heights[size_t(row) * dem.width + col]) / 1000.0 * exaggeration;
    };
    // The pole heights are the mean of the pole rows.
    auto poleHeight = [&](uint32_t row) {
      double s = 0;
      for (uint32_t c = 0; c < dem.width; ++c) s += heightAt(row, c);
      return s / dem.width;
    };

    std::FILE* f = std::fopen(output.string().c_str(), "wb");
    if (!f) throw std::runtime_error(output.string() + ": cannot write");
    const std::string header =
        "ply\nformat binary_little_endian 1.0\ncomment gimlod etopo_sphere from " + input.filename().string() +
        " step " + std::to_string(step) + " exaggeration " + std::to_string(exaggeration) +
        "\nelement vertex " + std::to_string(g.vertices()) +
        "\nproperty float x\nproperty float y\nproperty float z\nelement face " + std::to_string(g.triangles()) +
        "\nproperty list uchar int vertex_indices\nend_header\n";
    std::fwrite(header.data(), 1, header.size(), f);
    std::vector<float> ring(size_t(g.columns) * 3);
    auto put = [&](double lat, double lon, double h) {
      const double r = radius + h;
      const float p[3] = {float(r * std::cos(lat) * std::cos(lon)), float(r * std::cos(lat) * std::sin(lon)),
                          float(r * std::sin(lat))};
      std::fwrite(p, sizeof(float), 3, f);
    };
    // Vertex 0: south pole; 1 + k * columns + c: ring k, column c; last: north pole.
    put(-kPi / 2, 0.0, poleHeight(0));
    for (uint32_t row : rows) {
      const double lat = -kPi / 2 + kPi * row / double(dem.height - 1);
      for (uint32_t c = 0; c < g.columns; ++c)
        put(lat, 2 * kPi * double(c) / g.columns, heightAt(row, c * step));
    }
    put(kPi / 2, 0.0, poleHeight(dem.height - 1));

    // Counter-clockwise seen from outside: east is +column, north is +ring.
    const int32_t south = 0, north = int32_t(g.vertices() - 1);
    auto vid = [&](uint32_t k, uint32_t c) { return int32_t(1 + uint64_t(k) * g.columns + c % g.columns); };
    std::vector<uint8_t> buf;
    buf.reserve(size_t(g.columns) * 2 * 13);
    auto tri = [&](int32_t a, int32_t b, int32_t c) {
      buf.push_back(3);
      for (int32_t v : {a, b, c}) {
        uint8_t bytes[4];
        std::memcpy(bytes, &v, 4);
        buf.insert(buf.end(), bytes, bytes + 4);
      }
    };
    auto flush = [&] {
      std::fwrite(buf.data(), 1, buf.size(), f);
      buf.clear();
    };
    for (uint32_t c = 0; c < g.columns; ++c) tri(south, vid(0, c + 1), vid(0, c));
    flush();
    for (uint32_t k = 0; k + 1 < g.rings; ++k) {
      for (uint32_t c = 0; c < g.columns; ++c) {
        tri(vid(k, c), vid(k, c + 1), vid(k + 1, c + 1));
        tri(vid(k, c), vid(k + 1, c + 1), vid(k + 1, c));
      }
      flush();
    }
    for (uint32_t c = 0; c < g.columns; ++c) tri(vid(g.rings - 1, c), vid(g.rings - 1, c + 1), north);
    flush();
    const bool ok = std::fflush(f) == 0 && !std::ferror(f);
    std::fclose(f);
    if (!ok) throw std::runtime_error(output.string() + ": write failed");
    std::printf("%s: %llu vertices, %llu triangles (%u rings x %u columns + 2 poles), heights %.1f..%.1f m\n",
                output.string().c_str(), (unsigned long long)g.vertices(), (unsigned long long)g.triangles(),
                g.rings, g.columns, dem.minHeight, dem.maxHeight);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "etopo_sphere: %s\n", e.what());
    return 1;
  }
  return 0;
}
