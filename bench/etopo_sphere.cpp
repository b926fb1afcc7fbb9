// Turns a global lat/long DEM (e.g. ETOPO5, 4320 x 2161 samples from pole to pole) into a closed
// genus-0 sphere mesh for the large mesh-atlas benchmarks, every vertex displaced radially by
// elevation * exaggeration. Writes a binary little-endian PLY, streamed (the triangles are never
// held in memory). Two tessellations:
//
//   latlong (default): every interior grid row becomes a ring of vertices and each pole is closed by
//     a single vertex, so the rows next to the poles are long slivers (the pole fans far worse).
//   cube: the 6 faces of a cube, each an N x N grid of quads, projected to the sphere with the
//     equal-angle (tangent) warp so that all cells are near-uniform, each quad split along its
//     shorter diagonal; heights are bilinear in the DEM. No slivers, as in real scans.
//
//   etopo_sphere DEM -o OUT.ply [--tessellation latlong|cube] [--step K] [--cube-res N]
//                    [--exaggeration E] [--radius R]
//
// --step K (latlong) keeps every K-th column and row (K must divide the column count); the full
// ETOPO5 grid (K = 1) gives 18,653,760 triangles, K = 4 gives 1,164,240. --cube-res N (cube, quads
// per face side) gives 12 N^2 triangles: the default 1248 gives 18,690,048, 312 gives 1,168,128.
// Units are kilometres: radius R (default 6371) plus elevation (metres / 1000) * E (default 20).
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "atlas/terrain/dem.h"

namespace {

constexpr double kPi = 3.14159265358979323846;

// PLY vertex indices are signed 32-bit ints.
constexpr uint64_t kMaxVertices = 0x7fffffffull;
// The largest --cube-res whose 6 N^2 + 2 vertices have such indices.
constexpr uint32_t kMaxCubeRes = 18918;
static_assert(6ull * kMaxCubeRes * kMaxCubeRes + 2 <= kMaxVertices &&
              6ull * (kMaxCubeRes + 1) * (kMaxCubeRes + 1) + 2 > kMaxVertices);

struct SphereGrid {
  uint32_t columns = 0;  // vertices per ring
  uint32_t rings = 0;    // interior rows kept
  uint64_t vertices() const { return uint64_t(columns) * rings + 2; }
  uint64_t triangles() const { return uint64_t(columns) * 2 * (rings - 1) + uint64_t(columns) * 2; }
};

// The surface points of the integer lattice [0, N]^3, numbered in scan order (x fastest, then y,
// then z): whole layers at z = 0 and z = N, the 4N-point boundary of the square in between. Every
// cube edge and corner point is one vertex whichever face asks for it, so the mesh is closed.
struct CubeLattice {
  uint32_t n = 0;  // quads per face side
  uint64_t vertices() const { return 6 * uint64_t(n) * n + 2; }
  uint64_t triangles() const { return 12 * uint64_t(n) * n; }
  bool onSurface(uint32_t x, uint32_t y, uint32_t z) const {
    return x == 0 || x == n || y == 0 || y == n || z == 0 || z == n;
  }
  uint64_t index(uint32_t x, uint32_t y, uint32_t z) const {
    const uint64_t layer = uint64_t(n + 1) * (n + 1);
    if (z == 0) return x + uint64_t(n + 1) * y;
    const uint64_t start = layer + uint64_t(z - 1) * 4 * n;
    if (z == n || y == 0) return start + x + uint64_t(n + 1) * y;
    if (y == n) return start + 3 * uint64_t(n) - 1 + x;  // after row 0 and 2 points in each of rows 1..n-1
    return start + n + 1 + 2 * uint64_t(y - 1) + (x == n);
  }
};

// A cube face: the lattice points whose coordinate `fixed` is N (top) or 0, walked along axes u and
// v with u x v pointing outward, so that (u, v)-counter-clockwise quads are counter-clockwise from
// outside, as the lat/long triangles are.
struct CubeFace {
  int fixed, u, v;
  bool top;  // level N (else 0)
};
constexpr CubeFace kCubeFaces[6] = {{0, 1, 2, true},  {0, 2, 1, false}, {1, 2, 0, true},
                                    {1, 0, 2, false}, {2, 0, 1, true},  {2, 1, 0, false}};

// Binary little-endian PLY with float x y z vertices and int triangles, buffered writes.
class PlyWriter {
 public:
  PlyWriter(const std::filesystem::path& path, const std::string& comment, uint64_t vertices, uint64_t triangles)
      : path_(path), f_(std::fopen(path.string().c_str(), "wb")) {
    if (!f_) throw std::runtime_error(path.string() + ": cannot write");
    const std::string header = "ply\nformat binary_little_endian 1.0\ncomment " + comment + "\nelement vertex " +
                               std::to_string(vertices) +
                               "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                               std::to_string(triangles) + "\nproperty list uchar int vertex_indices\nend_header\n";
    append(header.data(), header.size());
  }
  ~PlyWriter() {
    if (f_) std::fclose(f_);
  }
  PlyWriter(const PlyWriter&) = delete;
  PlyWriter& operator=(const PlyWriter&) = delete;

  void vertex(const double p[3]) {
    const float q[3] = {float(p[0]), float(p[1]), float(p[2])};
    append(q, sizeof q);
  }
  void triangle(int32_t a, int32_t b, int32_t c) {
    uint8_t bytes[13] = {3};
    const int32_t v[3] = {a, b, c};
    std::memcpy(bytes + 1, v, sizeof v);
    append(bytes, sizeof bytes);
  }
  void close() {
    flush();
    const bool ok = std::fflush(f_) == 0 && !std::ferror(f_);
    std::fclose(f_);
    f_ = nullptr;
    if (!ok) throw std::runtime_error(path_.string() + ": write failed");
  }

 private:
  void append(const void* data, size_t size) {
    const auto* p = static_cast<const uint8_t*>(data);
    buf_.insert(buf_.end(), p, p + size);
    if (buf_.size() >= (1u << 20)) flush();
  }
  void flush() {
    std::fwrite(buf_.data(), 1, buf_.size(), f_);
    buf_.clear();
  }

  std::filesystem::path path_;
  std::FILE* f_;
  std::vector<uint8_t> buf_;
};

struct Options {
  std::filesystem::path input, output;
  double exaggeration = 20.0, radius = 6371.0;
};

double heightKm(const gimlod::DemRaster& dem, const Options& o, uint32_t row, uint32_t col) {
  return double(dem.heights[size_t(row) * dem.width + col]) / 1000.0 * o.exaggeration;
}

void writeLatLong(const gimlod::DemRaster& dem, const Options& o, uint32_t step) {
  if (dem.width % step || dem.height < 3 + 2 * step)
    throw std::invalid_argument("--step " + std::to_string(step) + " must divide the width (" +
                                std::to_string(dem.width) + ") and leave at least one interior row");
  // Rows 0 and height-1 are the poles; the interior rows step..height-1-step are rings.
  std::vector<uint32_t> rows;
  for (uint32_t r = step; r + step <= dem.height - 1; r += step) rows.push_back(r);
  SphereGrid g;
  g.columns = dem.width / step;
  g.rings = uint32_t(rows.size());
  if (g.vertices() > kMaxVertices) throw std::invalid_argument("too many vertices for a PLY int index");
  // The pole heights are the mean of the pole rows.
  auto poleHeight = [&](uint32_t row) {
    double s = 0;
    for (uint32_t c = 0; c < dem.width; ++c) s += heightKm(dem, o, row, c);
    return s / dem.width;
  };

  PlyWriter ply(o.output,
                "gimlod etopo_sphere from " + o.input.filename().string() + " step " + std::to_string(step) +
                    " exaggeration " + std::to_string(o.exaggeration),
                g.vertices(), g.triangles());
  auto put = [&](double lat, double lon, double h) {
    const double r = o.radius + h;
    const double p[3] = {r * std::cos(lat) * std::cos(lon), r * std::cos(lat) * std::sin(lon), r * std::sin(lat)};
    ply.vertex(p);
  };
  // Vertex 0: south pole; 1 + k * columns + c: ring k, column c; last: north pole.
  put(-kPi / 2, 0.0, poleHeight(0));
  for (uint32_t row : rows) {
    const double lat = -kPi / 2 + kPi * row / double(dem.height - 1);
    for (uint32_t c = 0; c < g.columns; ++c) put(lat, 2 * kPi * double(c) / g.columns, heightKm(dem, o, row, c * step));
  }
  put(kPi / 2, 0.0, poleHeight(dem.height - 1));

  // Counter-clockwise seen from outside: east is +column, north is +ring.
  const int32_t south = 0, north = int32_t(g.vertices() - 1);
  auto vid = [&](uint32_t k, uint32_t c) { return int32_t(1 + uint64_t(k) * g.columns + c % g.columns); };
  for (uint32_t c = 0; c < g.columns; ++c) ply.triangle(south, vid(0, c + 1), vid(0, c));
  for (uint32_t k = 0; k + 1 < g.rings; ++k) {
    for (uint32_t c = 0; c < g.columns; ++c) {
      ply.triangle(vid(k, c), vid(k, c + 1), vid(k + 1, c + 1));
      ply.triangle(vid(k, c), vid(k + 1, c + 1), vid(k + 1, c));
    }
  }
  for (uint32_t c = 0; c < g.columns; ++c) ply.triangle(vid(g.rings - 1, c), vid(g.rings - 1, c + 1), north);
  ply.close();
  std::printf("%s: %llu vertices, %llu triangles (%u rings x %u columns + 2 poles), heights %.1f..%.1f m\n",
              o.output.string().c_str(), (unsigned long long)g.vertices(), (unsigned long long)g.triangles(), g.rings,
              g.columns, dem.minHeight, dem.maxHeight);
}

void writeCube(const gimlod::DemRaster& dem, const Options& o, uint32_t n) {
  const CubeLattice cube{n};
  // Bilinear in the DEM (the lat/long mode's sample positions: column c at longitude 360 c / width,
  // rows pole to pole); longitude wraps, latitude is clamped at the pole rows.
  auto heightAt = [&](double lat, double lon) {
    double gx = lon / (2 * kPi) * dem.width;
    gx -= std::floor(gx / dem.width) * dem.width;
    const double gy = std::clamp((lat + kPi / 2) / kPi * (dem.height - 1), 0.0, double(dem.height - 1));
    const uint32_t c0 = std::min(uint32_t(gx), dem.width - 1), c1 = (c0 + 1) % dem.width;
    const uint32_t r0 = std::min(uint32_t(gy), dem.height - 2), r1 = r0 + 1;
    const double fx = gx - c0, fy = gy - r0;
    return (1 - fy) * ((1 - fx) * heightKm(dem, o, r0, c0) + fx * heightKm(dem, o, r0, c1)) +
           fy * ((1 - fx) * heightKm(dem, o, r1, c0) + fx * heightKm(dem, o, r1, c1));
  };
  // Lattice point -> displaced surface point. The warp tan(pi/4 t), t in [-1, 1] per coordinate,
  // makes the cells of every face subtend equal angles (the plain projection squeezes them ~5:1
  // in area towards the cube corners), and keeps each face on its cube plane, so that an edge
  // point is the same whichever face computes it.
  auto position = [&](const uint32_t l[3], double p[3]) {
    double s = 0;
    for (int a = 0; a < 3; ++a) {
      p[a] = std::tan(kPi / 4 * (2.0 * l[a] / n - 1));
      s += p[a] * p[a];
    }
    s = 1 / std::sqrt(s);
    for (int a = 0; a < 3; ++a) p[a] *= s;
    const double r = o.radius + heightAt(std::atan2(p[2], std::hypot(p[0], p[1])), std::atan2(p[1], p[0]));
    for (int a = 0; a < 3; ++a) p[a] *= r;
  };

  PlyWriter ply(o.output,
                "gimlod etopo_sphere from " + o.input.filename().string() + " cube res " + std::to_string(n) +
                    " exaggeration " + std::to_string(o.exaggeration),
                cube.vertices(), cube.triangles());
  // Vertices in CubeLattice order.
  for (uint32_t z = 0; z <= n; ++z)
    for (uint32_t y = 0; y <= n; ++y)
      for (uint32_t x = 0; x <= n; ++x) {
        if (!cube.onSurface(x, y, z)) continue;
        const uint32_t l[3] = {x, y, z};
        double p[3];
        position(l, p);
        ply.vertex(p);
      }

  // Triangles face by face, one row of quads at a time; the diagonal choice needs the positions,
  // recomputed for two lattice rows rather than held for all.
  struct Corner {
    double p[3];
    int32_t id;
  };
  auto dist2 = [](const Corner& a, const Corner& b) {
    double s = 0;
    for (int k = 0; k < 3; ++k) s += (a.p[k] - b.p[k]) * (a.p[k] - b.p[k]);
    return s;
  };
  std::vector<Corner> below(n + 1), above(n + 1);
  for (const CubeFace& face : kCubeFaces) {
    auto corners = [&](uint32_t j, std::vector<Corner>& row) {
      for (uint32_t i = 0; i <= n; ++i) {
        uint32_t l[3];
        l[face.fixed] = face.top ? n : 0;
        l[face.u] = i;
        l[face.v] = j;
        position(l, row[i].p);
        row[i].id = int32_t(cube.index(l[0], l[1], l[2]));
      }
    };
    corners(0, below);
    for (uint32_t j = 0; j < n; ++j) {
      corners(j + 1, above);
      for (uint32_t i = 0; i < n; ++i) {
        // Counter-clockwise from outside: p00, p10 (+u), p11, p01 (+v).
        const Corner &p00 = below[i], &p10 = below[i + 1], &p11 = above[i + 1], &p01 = above[i];
        if (dist2(p00, p11) <= dist2(p10, p01)) {
          ply.triangle(p00.id, p10.id, p11.id);
          ply.triangle(p00.id, p11.id, p01.id);
        } else {
          ply.triangle(p00.id, p10.id, p01.id);
          ply.triangle(p10.id, p11.id, p01.id);
        }
      }
      std::swap(below, above);
    }
  }
  ply.close();
  std::printf("%s: %llu vertices, %llu triangles (6 faces x %u x %u quads), heights %.1f..%.1f m\n",
              o.output.string().c_str(), (unsigned long long)cube.vertices(), (unsigned long long)cube.triangles(), n,
              n, dem.minHeight, dem.maxHeight);
}

int usage() {
  std::fprintf(stderr,
               "usage: etopo_sphere DEM -o OUT.ply [--tessellation latlong|cube] [--step K] [--cube-res N]\n"
               "                    [--exaggeration E] [--radius R]\n");
  return 2;
}

// A whole number from 1 to max, all of s (std::stoul would take "-1" as a huge value and "3x" as 3).
uint32_t wholeNumber(const std::string& option, const std::string& s, uint32_t max, const std::string& why = "") {
  uint64_t v = 0;
  const auto [end, error] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (error != std::errc() || end != s.data() + s.size() || v == 0 || v > max)
    throw std::invalid_argument(option + " needs a whole number from 1 to " + std::to_string(max) + why + ", not '" +
                                s + "'");
  return uint32_t(v);
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  std::string tessellation = "latlong";
  std::optional<uint32_t> step, cubeRes;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    try {
      if (a == "-o")
        o.output = next();
      else if (a == "--tessellation")
        tessellation = next();
      else if (a == "--step")
        step = wholeNumber(a, next(), 0x7fffffff);
      else if (a == "--cube-res")
        cubeRes = wholeNumber(a, next(), kMaxCubeRes, " (6 N^2 + 2 vertices must fit PLY int indices)");
      else if (a == "--exaggeration")
        o.exaggeration = std::stod(next());
      else if (a == "--radius")
        o.radius = std::stod(next());
      else if (!a.empty() && a[0] == '-')
        return usage();
      else
        o.input = a;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "etopo_sphere: %s\n", e.what());
      return usage();
    }
  }
  if (o.input.empty() || o.output.empty() || !(o.radius > 0) || !std::isfinite(o.exaggeration)) return usage();
  // An option of the other tessellation would be silently ignored: refuse it instead.
  const char* misfit = nullptr;
  if (tessellation != "latlong" && tessellation != "cube")
    misfit = "--tessellation must be latlong or cube";
  else if (tessellation == "latlong" && cubeRes)
    misfit = "--cube-res applies only to --tessellation cube";
  else if (tessellation == "cube" && step)
    misfit = "--step applies only to --tessellation latlong";
  if (misfit) {
    std::fprintf(stderr, "etopo_sphere: %s\n", misfit);
    return usage();
  }
  try {
    const gimlod::DemRaster dem = gimlod::loadDem(o.input);  // row 0 = south edge
    if (tessellation == "cube")
      writeCube(dem, o, cubeRes.value_or(1248));
    else
      writeLatLong(dem, o, step.value_or(1));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "etopo_sphere: %s\n", e.what());
    return 1;
  }
  return 0;
}
