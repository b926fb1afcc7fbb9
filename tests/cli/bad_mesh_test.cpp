// Bad mesh input, through the reader API and through `gimlod build`:
// every case is hand-made here, in a temporary directory, from a small UV sphere. Each one is
// either repaired, with the repair counted (MeshReadStats, stats.json and the build's printout),
// or rejected with exit code 2 (an InputError) and a message that names the file and the problem;
// a rejected build leaves neither an atlas nor its staging directory behind, and an earlier atlas
// at the output path stays as it was. The tool runs under `timeout 60`, so a hang fails the test
// (exit 124) instead of blocking it, and a crash shows as a signal exit (134, 139), not 2.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

#include <glm/vector_relational.hpp>
#include <nlohmann/json.hpp>

#include "atlas/mesh/mesh_atlas.h"
#include "atlas/mesh/mesh_io.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;
using Tri = std::array<uint32_t, 3>;

// ---- hand-made meshes ---------------------------------------------------------------------------

struct Mesh {
  std::vector<glm::vec3> v;
  std::vector<Tri> f;
};

// A closed UV sphere (radius r, centre c): n rings, 2n segments, one vertex per pole; outward
// winding; 4n^2 - 4n triangles.
Mesh sphere(uint32_t n, glm::vec3 c = glm::vec3(0), float r = 1.f) {
  Mesh m;
  m.v.push_back(c + glm::vec3(0, 0, r));
  for (uint32_t i = 1; i < n; ++i)
    for (uint32_t j = 0; j < 2 * n; ++j) {
      const double th = M_PI * i / n, ph = M_PI * j / n;
      m.v.push_back(c + r * glm::vec3(float(std::sin(th) * std::cos(ph)), float(std::sin(th) * std::sin(ph)),
                                      float(std::cos(th))));
    }
  m.v.push_back(c + glm::vec3(0, 0, -r));
  const uint32_t south = uint32_t(m.v.size() - 1);
  auto ring = [&](uint32_t i, uint32_t j) { return 1 + (i - 1) * 2 * n + j % (2 * n); };
  for (uint32_t j = 0; j < 2 * n; ++j) {
    m.f.push_back({0, ring(1, j), ring(1, j + 1)});
    m.f.push_back({south, ring(n - 1, j + 1), ring(n - 1, j)});
  }
  for (uint32_t i = 1; i + 1 < n; ++i)
    for (uint32_t j = 0; j < 2 * n; ++j) {
      m.f.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
      m.f.push_back({ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
  return m;
}

// Appends b to a (a second component).
void append(Mesh& a, const Mesh& b) {
  const uint32_t base = uint32_t(a.v.size());
  a.v.insert(a.v.end(), b.v.begin(), b.v.end());
  for (const Tri& t : b.f) a.f.push_back({t[0] + base, t[1] + base, t[2] + base});
}

std::string num(float x) {
  if (std::isnan(x)) return "nan";
  if (std::isinf(x)) return x > 0 ? "inf" : "-inf";
  char b[32];
  std::snprintf(b, sizeof b, "%.9g", double(x));
  return b;
}

std::string objText(const Mesh& m) {
  std::string s = "# hand-made\n";
  for (const glm::vec3& p : m.v) s += "v " + num(p.x) + " " + num(p.y) + " " + num(p.z) + "\n";
  for (const Tri& t : m.f)
    s += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " + std::to_string(t[2] + 1) + "\n";
  return s;
}

std::string offText(const Mesh& m) {
  std::string s = "OFF\n" + std::to_string(m.v.size()) + " " + std::to_string(m.f.size()) + " 0\n";
  for (const glm::vec3& p : m.v) s += num(p.x) + " " + num(p.y) + " " + num(p.z) + "\n";
  for (const Tri& t : m.f)
    s += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + "\n";
  return s;
}

std::string plyHeader(const std::string& format, size_t vertices, size_t faces) {
  return "ply\nformat " + format + " 1.0\nelement vertex " + std::to_string(vertices) +
         "\nproperty float x\nproperty float y\nproperty float z\nelement face " + std::to_string(faces) +
         "\nproperty list uchar int vertex_indices\nend_header\n";
}

std::string plyAscii(const Mesh& m) {
  std::string s = plyHeader("ascii", m.v.size(), m.f.size());
  for (const glm::vec3& p : m.v) s += num(p.x) + " " + num(p.y) + " " + num(p.z) + "\n";
  for (const Tri& t : m.f)
    s += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + "\n";
  return s;
}

template <typename T>
void putLE(std::string& s, T v) {
  auto a = std::bit_cast<std::array<char, sizeof(T)>>(v);
  if (std::endian::native == std::endian::big) std::reverse(a.begin(), a.end());
  s.append(a.data(), a.size());
}

std::string plyBinary(const Mesh& m) {
  std::string s = plyHeader("binary_little_endian", m.v.size(), m.f.size());
  for (const glm::vec3& p : m.v)
    for (int k = 0; k < 3; ++k) putLE<float>(s, p[k]);
  for (const Tri& t : m.f) {
    putLE<uint8_t>(s, 3);
    for (uint32_t i : t) putLE<int32_t>(s, int32_t(i));
  }
  return s;
}

std::string stlBinary(const Mesh& m) {
  std::string s(80, ' ');
  putLE<uint32_t>(s, uint32_t(m.f.size()));
  for (const Tri& t : m.f) {
    for (int k = 0; k < 3; ++k) putLE<float>(s, 0.f);
    for (uint32_t i : t)
      for (int k = 0; k < 3; ++k) putLE<float>(s, m.v[i][k]);
    putLE<uint16_t>(s, 0);
  }
  return s;
}

std::string stlAscii(const Mesh& m) {
  std::string s = "solid hand\n";
  for (const Tri& t : m.f) {
    s += " facet normal 0 0 1\n  outer loop\n";
    for (uint32_t i : t) s += "   vertex " + num(m.v[i].x) + " " + num(m.v[i].y) + " " + num(m.v[i].z) + "\n";
    s += "  endloop\n endfacet\n";
  }
  return s + "endsolid hand\n";
}

// ---- the fixture ---------------------------------------------------------------------------------

class BadMesh : public ::testing::Test {
 protected:
  fs::path write(const std::string& name, const std::string& bytes) { return dir_.write(name, bytes); }

  // `timeout 60 gimlod build IN -o DIR/out.atlas ARGS`; the exit status (124: it hung).
  int build(const fs::path& in, const std::string& args = "--charts 8 --chart-size 9 --depth 2") {
    out_ = dir_.path() / "out.atlas";
    const int rc = test::runCommand(
        "timeout 60 " + test::appPath().string() + " build '" + in.string() + "' -o '" + out_.string() + "' " + args,
        &output_);
    EXPECT_NE(rc, 124) << in << " " << args << ": the build hung (killed after 60 s)\n" << output_;
    return rc;
  }

  // The build is rejected with an InputError (exit 2) naming the file (or option) and every
  // fragment, and leaves nothing behind.
  void expectRejected(const fs::path& in, std::initializer_list<std::string> fragments,
                      const std::string& args = "--charts 8 --chart-size 9 --depth 2", const std::string& names = "") {
    SCOPED_TRACE(in.filename().string() + " " + args);
    EXPECT_EQ(build(in, args), 2) << output_;
    const std::string named = names.empty() ? in.filename().string() : names;
    EXPECT_NE(output_.find(named), std::string::npos) << output_;
    for (const std::string& s : fragments) EXPECT_NE(output_.find(s), std::string::npos) << s << "\n" << output_;
    expectNothingLeft();
  }

  // No atlas at the output path and no staging directory (".out.atlas.partial-*") beside it.
  void expectNothingLeft() {
    EXPECT_FALSE(fs::exists(out_)) << output_;
    for (const auto& e : fs::directory_iterator(dir_.path()))
      EXPECT_EQ(e.path().filename().string().find("out.atlas"), std::string::npos)
          << "left behind: " << e.path() << "\n"
          << output_;
  }

  // Reading the file through the API throws an InputError naming it and every fragment.
  void expectReadError(const fs::path& f, std::initializer_list<std::string> fragments) {
    SCOPED_TRACE(f.filename().string());
    try {
      readMesh(f);
      ADD_FAILURE() << "expected InputError for " << f;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(f.string()), std::string::npos) << msg;
      for (const std::string& s : fragments) EXPECT_NE(msg.find(s), std::string::npos) << s << "\n" << msg;
    }
  }

  // Both: the reader and the tool reject the file.
  void expectBothReject(const fs::path& f, std::initializer_list<std::string> fragments) {
    expectReadError(f, fragments);
    expectRejected(f, fragments);
  }

  // A successful build: its stats.json.
  nlohmann::json built(const fs::path& in, const std::string& args = "--charts 8 --chart-size 9 --depth 2") {
    SCOPED_TRACE(in.filename().string() + " " + args);
    const int rc = build(in, args);
    EXPECT_EQ(rc, 0) << output_;
    if (rc != 0) return nlohmann::json::object();
    std::ifstream f(out_ / "stats.json");
    nlohmann::json j = nlohmann::json::parse(f);
    EXPECT_TRUE(fs::exists(out_ / "atlas.json"));
    for (const auto& e : fs::directory_iterator(dir_.path()))
      EXPECT_EQ(e.path().filename().string().find(".out.atlas.partial"), std::string::npos) << e.path();
    return j;
  }

  // The value after "label" on the printout's line that holds it.
  std::string printed(const std::string& label) const {
    const size_t at = output_.find(label);
    if (at == std::string::npos) return "";
    return output_.substr(at, output_.find('\n', at) - at);
  }

  test::TempDir dir_{"gimlod-bad-mesh"};
  fs::path out_;
  std::string output_;
};

// ---- rejected ------------------------------------------------------------------------------------

TEST_F(BadMesh, EmptyFilesOfEveryFormat) {
  for (const char* name : {"empty.ply", "empty.obj", "empty.off", "empty.stl"})
    expectBothReject(write(name, ""), {"empty file"});
  // Whitespace only is no better.
  expectBothReject(write("blank.obj", "\n\n  \n"), {"no faces"});
}

TEST_F(BadMesh, TruncatedBinaryPly) {
  const std::string full = plyBinary(sphere(6));
  const size_t header = full.find("end_header\n") + 11;
  // In the vertices (caught by the size check before anything is allocated), in the faces (caught
  // when the faces run out), and one byte short.
  for (size_t keep : {header + 7, header + (full.size() - header) / 2, full.size() - 1}) {
    const fs::path f = write("cut" + std::to_string(keep) + ".ply", full.substr(0, keep));
    expectBothReject(f, {"truncated"});
  }
  // Cut inside the header.
  expectBothReject(write("cut_header.ply", full.substr(0, header / 2)), {"bad PLY header", "end_header"});
}

TEST_F(BadMesh, FaceIndexPastTheVertexCount) {
  Mesh m = sphere(5);
  const uint32_t nv = uint32_t(m.v.size());
  m.f[7][2] = nv;  // one past the last vertex
  expectBothReject(write("past.ply", plyBinary(m)), {"face' element 7", "index " + std::to_string(nv), "out of range"});
  expectBothReject(write("past_ascii.ply", plyAscii(m)), {"face' element 7", "out of range"});
  expectBothReject(write("past.off", offText(m)), {"face 7", "out of range"});
  expectBothReject(write("past.obj", objText(m)), {"face 7", "index " + std::to_string(nv + 1), "out of range"});
  // Negative: relative OBJ indices reaching before the first vertex; PLY has no negative indices.
  expectBothReject(write("before.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -9\n"), {"index -9", "out of range"});
  m = sphere(5);
  m.f[3][0] = uint32_t(-5);
  expectBothReject(write("negative.ply", plyBinary(m)), {"face' element 3", "index -5"});
}

TEST_F(BadMesh, CorruptPlyHeaders) {
  const std::string good = plyAscii(sphere(4));
  auto with = [&](const std::string& from, const std::string& to) {
    std::string s = good;
    const size_t at = s.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) s.replace(at, from.size(), to);
    return s;
  };
  expectBothReject(write("type.ply", with("property float y", "property float128 y")),
                   {"unknown PLY property type 'float128'"});
  expectBothReject(write("listtype.ply", with("list uchar int", "list uchar quadword")),
                   {"unknown PLY property type 'quadword'"});
  expectBothReject(write("keyword.ply", with("element face", "elephant face")), {"unknown PLY header keyword"});
  expectBothReject(write("magic.ply", with("ply\n", "plY\n")), {"not a PLY file"});
  expectBothReject(write("format.ply", with("format ascii", "format ebcdic")), {"unsupported PLY format"});
  // Counts that overflow: more vertices than the file could hold, a count past int64, and a
  // negative count.
  const std::string vcount = "element vertex " + std::to_string(sphere(4).v.size());
  expectBothReject(write("overflow.ply", with(vcount, "element vertex 99999999999")),
                   {"99999999999 'vertex' elements", "truncated or corrupt"});
  expectBothReject(write("overflow_bin.ply", plyHeader("binary_little_endian", 99999999999ull, 1)),
                   {"99999999999 'vertex' elements"});
  expectBothReject(write("overflow64.ply", with(vcount, "element vertex 99999999999999999999")), {"too large"});
  expectBothReject(write("negative.ply", with(vcount, "element vertex -3")), {"bad element line"});
  expectBothReject(write("noxyz.ply", with("property float z", "property float w")), {"no 'z'"});
  expectBothReject(write("points.ply", plyHeader("ascii", 3, 0) + "0 0 0\n1 0 0\n0 1 0\n"), {"no faces"});
}

TEST_F(BadMesh, TruncatedTextFormats) {
  const Mesh m = sphere(5);
  const std::string off = offText(m);
  expectBothReject(write("cut.off", off.substr(0, off.size() * 2 / 3)), {"truncated"});
  const std::string stl = stlAscii(m);
  // Cut in the middle of a line, and at a line break inside a facet.
  expectBothReject(write("cut_mid.stl", stl.substr(0, stl.size() / 2 + 3)), {"truncated"});
  expectBothReject(write("cut_line.stl", stl.substr(0, stl.find("endloop", stl.size() / 2))), {"ends inside a facet"});
  const std::string bin = stlBinary(m);
  expectBothReject(write("cut_bin.stl", bin.substr(0, bin.size() - 30)),
                   {"truncated binary STL", std::to_string(m.f.size()) + " facets"});
  expectBothReject(write("cut_head.stl", bin.substr(0, 50)), {"truncated binary STL"});
  const std::string ply = plyAscii(m);
  expectBothReject(write("cut_ascii.ply", ply.substr(0, ply.size() - 4)), {"truncated"});
  // An OBJ cut inside a vertex line says where.
  const std::string obj = objText(m);
  expectBothReject(write("cut.obj", obj.substr(0, obj.find("\nv ", obj.size() / 4) + 5)),
                   {"vertex needs 3 coordinates", "truncated"});
}

TEST_F(BadMesh, NothingLeftAfterRepair) {
  // Every triangle has zero area (collinear), or all vertices are one point, or every triangle
  // uses a non-finite vertex: the repairs leave nothing to build from.
  expectBothReject(write("collinear.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\nf 1 2 4\n"),
                   {"no valid triangles", "3 degenerate"});
  Mesh point = sphere(4);
  for (glm::vec3& p : point.v) p = glm::vec3(1.5f, -2.f, 3.f);
  expectBothReject(write("point.ply", plyBinary(point)),
                   {"no valid triangles", std::to_string(point.f.size()) + " degenerate"});
  expectBothReject(write("point.stl", stlBinary(point)), {"no valid triangles"});
  expectBothReject(write("point.off", offText(point)), {"no valid triangles"});
  Mesh nan = sphere(4);
  for (glm::vec3& p : nan.v) p.y = std::numeric_limits<float>::quiet_NaN();
  expectBothReject(write("nan.obj", objText(nan)),
                   {"no valid triangles", std::to_string(nan.f.size()) + " with a NaN or infinite coordinate"});
  // Faces with fewer than 3 corners only.
  expectBothReject(write("short.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n1 2\n"),
                   {"no valid triangles", "fewer than 3 corners"});
  // A point cloud.
  expectBothReject(write("cloud.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"), {"no faces"});
}

TEST_F(BadMesh, AbsurdOptions) {
  const fs::path f = write("sphere.ply", plyBinary(sphere(5)));
  const std::string base = "--chart-size 9 --depth 2 ";
  expectRejected(f, {"--chart-error"}, base + "--charts 0 --chart-error 0", "--chart-error");
  expectRejected(f, {"--chart-error"}, base + "--charts 0 --chart-error -1", "--chart-error");
  for (const char* size : {"4", "3", "16", "100000", "16385"})
    expectRejected(f, {"--chart-size"}, std::string("--chart-size ") + size, "--chart-size");
  expectRejected(f, {"must be at least 64 MiB"}, base + "--max-memory 1K", "--max-memory");
  expectRejected(f, {"positive size"}, base + "--max-memory 0", "--max-memory");
  expectRejected(f, {"unknown unit"}, base + "--max-memory 4X", "--max-memory");
  // Geometry images that cannot fit the memory cap are refused before they are allocated.
  expectRejected(f, {"--max-memory", "GiB of geometry images"}, "--chart-size 8193 --charts 8", "sphere.ply");
  expectRejected(f, {"--threads"}, base + "--threads 100000", "--threads");
  expectRejected(f, {"--depth"}, "--chart-size 9 --depth 0", "--depth");
  expectRejected(f, {"--repair-rounds"}, base + "--repair-rounds 17", "--repair-rounds");
  expectRejected(f, {"--repair-budget"}, base + "--repair-budget -1", "--repair-budget");
  expectRejected(f, {"--repair-budget"}, base + "--flip-repair-budget 101", "--repair-budget");  // the old name
  expectRejected(f, {"--sample-error"}, base + "--sample-error -0.01", "--sample-error");
  expectRejected(f, {"--sample-error"}, base + "--sample-error 50", "--sample-error");
  expectRejected(f, {"--charts", "whole number"}, base + "--charts many", "--charts");
  expectRejected(f, {"--charts", "whole number"}, base + "--charts -3", "--charts");
  expectRejected(f, {"--position-bits"}, base + "--position-bits 23", "--position-bits");
  expectRejected(f, {"--position-tolerance"}, base + "--position-tolerance -0.1", "--position-tolerance");
  expectRejected(f, {"--position-tolerance"}, base + "--position-tolerance 5", "--position-tolerance");
  expectRejected(f, {"--normal-tolerance"}, base + "--normal-tolerance 17", "--normal-tolerance");
  // A choice outside the list: CLI11's validation error (its own exit code), naming the option.
  EXPECT_NE(build(f, base + "--normals maybe"), 0);
  EXPECT_NE(output_.find("--normals: maybe not in {auto,stored,derived}"), std::string::npos) << output_;
  expectNothingLeft();
  EXPECT_EQ(build(f, base + "--charts 8 --repair-rounds 0"), 0) << output_;  // in range: builds
  EXPECT_EQ(build(f, base + "--charts 8 --position-tolerance 0 --normal-tolerance 0 --normals derived"), 0) << output_;
  EXPECT_EQ(build(f, base + "--charts auto --sample-error 0"), 0) << output_;

  // --charts 0 without --chart-error uses the default error target; --charts far above the
  // triangle count stops at what the mesh allows (every patch holds at least one triangle).
  const size_t triangles = sphere(5).f.size();
  nlohmann::json s = built(f, base + "--charts 0");
  EXPECT_GE(s["charting"]["patches"].get<uint64_t>(), 1u);
  EXPECT_LE(s["charting"]["patches"].get<uint64_t>(), triangles);
  s = built(f, base + "--charts 1000000000");
  EXPECT_GE(s["charting"]["patches"].get<uint64_t>(), 1u);
  EXPECT_LE(s["charting"]["patches"].get<uint64_t>(), triangles);
  s = built(f, base + "--charts 1");
  EXPECT_GE(s["charting"]["patches"].get<uint64_t>(), 1u);
}

TEST_F(BadMesh, FailedRebuildKeepsTheEarlierAtlas) {
  const fs::path good = write("good.off", offText(sphere(5)));
  const nlohmann::json first = built(good);
  const std::string before = [&] {
    std::ifstream f(out_ / "stats.json");
    return std::string((std::istreambuf_iterator<char>(f)), {});
  }();
  ASSERT_FALSE(before.empty());
  const std::string ply = plyBinary(sphere(5));
  EXPECT_EQ(build(write("cut.ply", ply.substr(0, ply.size() - 9))), 2) << output_;
  EXPECT_EQ(build(write("point.obj", "v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n")), 2) << output_;
  const std::string after = [&] {
    std::ifstream f(out_ / "stats.json");
    return std::string((std::istreambuf_iterator<char>(f)), {});
  }();
  EXPECT_EQ(after, before);
  EXPECT_TRUE(fs::exists(out_ / "atlas.json"));
  for (const auto& e : fs::directory_iterator(dir_.path()))
    EXPECT_EQ(e.path().filename().string().find(".partial"), std::string::npos) << e.path();
}

TEST_F(BadMesh, StagingLeftByAKilledBuildIsRemovedByTheNext) {
  // A build killed by a signal cannot clean up: its ".out.atlas.partial-PID-*" stays. The next
  // build at that path removes those of processes that are gone, and keeps a live one's.
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  ASSERT_GT(child, 0);
  ASSERT_EQ(::waitpid(child, nullptr, 0), child);  // a pid that no longer runs
  const fs::path dead = dir_.path() / (".out.atlas.partial-" + std::to_string(child) + "-5eed");
  const fs::path live = dir_.path() / (".out.atlas.partial-" + std::to_string(::getpid()) + "-11fe");
  for (const fs::path& d : {dead, live, fs::path(dead.string() + ".old")}) {
    fs::create_directories(d / "charts");
    write(fs::relative(d / "charts" / "c0.chart", dir_.path()).string(), "half-written");
  }
  // Rejected after staging began (the geometry images would not fit --max-memory).
  EXPECT_EQ(build(write("sphere.off", offText(sphere(4))), "--chart-size 8193 --charts 8"), 2) << output_;
  EXPECT_NE(output_.find("GiB of geometry images"), std::string::npos) << output_;
  EXPECT_FALSE(fs::exists(dead));
  EXPECT_FALSE(fs::exists(dead.string() + ".old"));
  EXPECT_TRUE(fs::exists(live));
  fs::remove_all(live);
  built(write("one.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"));
}

// ---- repaired and counted ------------------------------------------------------------------------

TEST_F(BadMesh, NonFiniteCoordinatesAreDroppedAndCounted) {
  Mesh m = sphere(5);
  const uint32_t nv = uint32_t(m.v.size());
  m.v.push_back({std::numeric_limits<float>::quiet_NaN(), 0, 0});
  m.v.push_back({0, std::numeric_limits<float>::infinity(), 0});
  m.v.push_back({0, 0, -std::numeric_limits<float>::infinity()});  // unused
  const size_t kept = m.f.size();
  m.f.push_back({0, 1, nv});
  m.f.push_back({nv, nv + 1, 2});
  m.f.push_back({3, nv + 1, 4});
  for (const fs::path& f : {write("nan.obj", objText(m)), write("nan.ply", plyBinary(m))}) {
    SCOPED_TRACE(f.filename().string());
    const IndexedMesh r = readMesh(f);
    EXPECT_EQ(r.stats.nonFiniteVertices, 3u);
    EXPECT_EQ(r.stats.droppedNonFinite, 3u);
    EXPECT_EQ(r.triangles.size(), kept);
    const nlohmann::json s = built(f);
    EXPECT_EQ(s["read"]["non_finite_vertices"], 3);
    EXPECT_EQ(s["read"]["dropped_non_finite"], 3);
    EXPECT_EQ(s["read"]["triangles"], kept);
    EXPECT_NE(printed("  input  ").find("dropped: 3 non-finite"), std::string::npos) << output_;
    // The atlas covers the finite sphere only.
    for (int k = 0; k < 6; ++k) EXPECT_LE(std::abs(s["bounds"][k].get<double>()), 1.0 + 1e-5) << s["bounds"];
  }
  // STL (positions per facet).
  const fs::path stl = write("nan.stl", stlBinary(m));
  EXPECT_EQ(readMesh(stl).stats.droppedNonFinite, 3u);
  EXPECT_EQ(built(stl)["read"]["dropped_non_finite"], 3);
}

TEST_F(BadMesh, DegenerateAndDuplicateTrianglesAreDroppedAndCounted) {
  Mesh m = sphere(5);
  const size_t kept = m.f.size();
  const uint32_t nv = uint32_t(m.v.size());
  m.v.push_back(m.v[5]);                                     // a copy of vertex 5 (same position)
  m.v.insert(m.v.end(), {{0, 0, 5}, {1, 0, 5}, {2, 0, 5}});  // on one line
  m.f.push_back(m.f[4]);                                     // exact duplicate
  m.f.push_back({m.f[9][2], m.f[9][1], m.f[9][0]});          // reversed duplicate
  m.f.push_back({m.f[11][1], m.f[11][2], m.f[11][0]});       // rotated duplicate
  m.f.push_back({6, 6, 7});                                  // repeated index
  m.f.push_back({5, nv, 8});                                 // coincident positions: zero area
  m.f.push_back({nv + 1, nv + 3, nv + 2});                   // collinear: zero area
  for (const fs::path& f : {write("degdup.off", offText(m)), write("degdup.ply", plyAscii(m))}) {
    SCOPED_TRACE(f.filename().string());
    const IndexedMesh r = readMesh(f);
    EXPECT_EQ(r.stats.droppedDuplicate, 3u);
    EXPECT_EQ(r.stats.droppedDegenerate, 3u);
    EXPECT_EQ(r.triangles.size(), kept);
    EXPECT_EQ(r.stats.trianglesRead,
              r.stats.trianglesOut + r.stats.droppedNonFinite + r.stats.droppedDegenerate + r.stats.droppedDuplicate);
    const nlohmann::json s = built(f);
    EXPECT_EQ(s["read"]["dropped_duplicate"], 3);
    EXPECT_EQ(s["read"]["dropped_degenerate"], 3);
    EXPECT_EQ(s["read"]["triangles_read"], m.f.size());
    EXPECT_EQ(s["charting"]["triangles"], kept);
    EXPECT_NE(printed("  input  ").find("3 degenerate, 3 duplicate"), std::string::npos) << output_;
  }
  // An unwelded copy of the sphere (every triangle with its own 3 vertices, as STL stores it) is
  // welded back by the charting: the same closed surface, nothing open.
  Mesh soup;
  for (const Tri& t : sphere(5).f) {
    const uint32_t b = uint32_t(soup.v.size());
    for (uint32_t i : t) soup.v.push_back(sphere(5).v[i]);
    soup.f.push_back({b, b + 1, b + 2});
  }
  const nlohmann::json s = built(write("soup.obj", objText(soup)));
  EXPECT_GT(s["charting"]["vertices_welded"].get<uint64_t>(), 0u);
  EXPECT_EQ(s["charting"]["boundary_edges"], 0);
  EXPECT_EQ(s["charting"]["triangles"], kept);
}

TEST_F(BadMesh, NonManifoldEdgesAndVerticesAreSplitAndCounted) {
  // Fins: three extra triangles on one sphere edge (5 triangles on it).
  Mesh fins = sphere(5);
  const Tri e = fins.f[20];
  for (int k = 0; k < 3; ++k) {
    fins.v.push_back(glm::vec3(2.f + float(k), 2.f, 2.f));
    fins.f.push_back({e[0], e[1], uint32_t(fins.v.size() - 1)});
  }
  nlohmann::json s = built(write("fins.obj", objText(fins)));
  EXPECT_EQ(s["charting"]["non_manifold_edges"], 1);
  EXPECT_GT(s["charting"]["vertices_split"].get<uint64_t>(), 0u);
  EXPECT_EQ(s["charting"]["triangles"], fins.f.size());  // repaired, not dropped
  EXPECT_NE(printed("  repaired  ").find("1 non-manifold edges"), std::string::npos) << output_;
  EXPECT_EQ(readMesh(dir_.path() / "fins.obj").triangles.size(), fins.f.size());  // the reader keeps them

  // A bow-tie: one triangle touching the sphere at its north pole only.
  Mesh bow = sphere(5);
  bow.v.push_back({0.5f, 0.f, 1.5f});
  bow.v.push_back({0.f, 0.5f, 1.5f});
  bow.f.push_back({0, uint32_t(bow.v.size() - 2), uint32_t(bow.v.size() - 1)});
  s = built(write("bowtie.ply", plyBinary(bow)));
  EXPECT_EQ(s["charting"]["non_manifold_vertices"], 1);
  EXPECT_EQ(s["charting"]["vertices_split"], 1);
  EXPECT_EQ(s["charting"]["triangles"], bow.f.size());

  // Two spheres sharing one vertex position (welded into a non-manifold vertex).
  Mesh pair = sphere(5);
  append(pair, sphere(5, glm::vec3(0, 0, 2)));  // its south pole is the first's north pole
  s = built(write("kissing.stl", stlBinary(pair)));
  EXPECT_EQ(s["charting"]["non_manifold_vertices"], 1);
  EXPECT_EQ(s["charting"]["boundary_edges"], 0);

  // Inconsistent orientation: every other triangle flipped.
  Mesh flipped = sphere(5);
  for (size_t i = 0; i < flipped.f.size(); i += 2) std::swap(flipped.f[i][1], flipped.f[i][2]);
  s = built(write("flipped.obj", objText(flipped)));
  EXPECT_GT(s["charting"]["non_manifold_edges"].get<uint64_t>(), 0u);
  EXPECT_EQ(s["charting"]["triangles"], flipped.f.size());
}

// How many atlas surface vertices (level 0) lie in the box [lo, hi].
size_t atlasVerticesIn(const fs::path& atlas, glm::vec3 lo, glm::vec3 hi) {
  const AtlasSurface a = readAtlasSurface(atlas, 0);
  size_t n = 0;
  for (const glm::vec3& p : a.positions)
    if (glm::all(glm::greaterThanEqual(p, lo)) && glm::all(glm::lessThanEqual(p, hi))) ++n;
  return n;
}

TEST_F(BadMesh, SeveralComponentsAreAllCharted) {
  // Two disjoint spheres: both are in the atlas, each closed.
  Mesh two = sphere(6);
  append(two, sphere(6, glm::vec3(5, 0, 0), 0.5f));
  nlohmann::json s = built(write("two.ply", plyBinary(two)));
  EXPECT_EQ(s["charting"]["boundary_edges"], 0);
  EXPECT_EQ(s["charting"]["triangles"], two.f.size());
  EXPECT_GT(atlasVerticesIn(out_, glm::vec3(-1.01f), glm::vec3(1.01f)), 0u);
  EXPECT_GT(atlasVerticesIn(out_, glm::vec3(4.49f, -0.51f, -0.51f), glm::vec3(5.51f, 0.51f, 0.51f)), 0u);
  EXPECT_EQ(atlasVerticesIn(out_, glm::vec3(1.1f, -2.f, -2.f), glm::vec3(4.4f, 2.f, 2.f)), 0u);

  // A sphere plus one stray triangle far away: the triangle is its own patch, not dropped.
  Mesh stray = sphere(6);
  stray.v.push_back({10.f, 10.f, 10.f});
  stray.v.push_back({10.2f, 10.f, 10.f});
  stray.v.push_back({10.f, 10.2f, 10.f});
  stray.f.push_back({uint32_t(stray.v.size() - 3), uint32_t(stray.v.size() - 2), uint32_t(stray.v.size() - 1)});
  s = built(write("stray.obj", objText(stray)));
  EXPECT_EQ(s["charting"]["triangles"], stray.f.size());
  EXPECT_EQ(s["charting"]["boundary_edges"], 3);  // the stray triangle's border
  EXPECT_GT(atlasVerticesIn(out_, glm::vec3(9.99f, 9.99f, 9.99f), glm::vec3(10.21f, 10.21f, 10.01f)), 0u);
  // On the position lattice: 2^-14 over this mesh's diagonal of about 19, at the default 2^18 steps.
  EXPECT_NEAR(s["bounds"][3].get<double>(), 10.2, std::exp2(-15.0));

  // Many components: 40 separate triangles, more than the --charts target.
  Mesh confetti;
  for (uint32_t i = 0; i < 40; ++i) {
    const glm::vec3 o(float(i % 7) * 3.f, float(i / 7) * 3.f, float(i % 3));
    confetti.v.insert(confetti.v.end(), {o, o + glm::vec3(1, 0, 0), o + glm::vec3(0, 1, 0.5f)});
    confetti.f.push_back({3 * i, 3 * i + 1, 3 * i + 2});
  }
  s = built(write("confetti.off", offText(confetti)));
  EXPECT_EQ(s["charting"]["patches"], 40);
  EXPECT_EQ(s["charting"]["triangles"], 40);
}

TEST_F(BadMesh, SingleTriangle) {
  const fs::path f = write("one.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  const IndexedMesh r = readMesh(f);
  EXPECT_EQ(r.triangles.size(), 1u);
  const nlohmann::json s = built(f);
  EXPECT_EQ(s["charting"]["patches"], 1);
  EXPECT_EQ(s["charts"], 3);  // a triangle is a 3-sided patch: 3 quads
  EXPECT_EQ(s["charting"]["boundary_edges"], 3);
  // Also as a single binary STL facet and a one-face PLY.
  EXPECT_EQ(built(write("one.stl", stlBinary(Mesh{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}})))["charts"], 3);
  EXPECT_EQ(built(write("one.ply", plyAscii(Mesh{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}})))["charts"], 3);
}

TEST_F(BadMesh, ObjRelativeIndicesAndPolygons) {
  // A cube of quads, some with negative (relative) indices, some with texture / normal slashes.
  const std::string cube =
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
      "f -8 -5 -6 -7\n"      // bottom 1 4 3 2
      "f 5/1 6/2 7/3 8/4\n"  // top
      "f 1//1 2//1 6//1 5//1\n"
      "f -6 -5 -1 -2\n"  // 3 4 8 7
      "f 2 3 7 6\n"
      "f 1 5 8 4\n"
      "f 1 2\n";  // a face with 2 corners: skipped and counted
  const fs::path f = write("cube.obj", cube);
  const IndexedMesh r = readMesh(f);
  EXPECT_EQ(r.triangles.size(), 12u);
  EXPECT_EQ(r.stats.polygonsFanned, 6u);
  EXPECT_EQ(r.stats.shortFaces, 1u);
  const nlohmann::json s = built(f);
  EXPECT_EQ(s["read"]["polygons_fanned"], 6);
  EXPECT_EQ(s["read"]["short_faces"], 1);
  EXPECT_EQ(s["charting"]["boundary_edges"], 0);  // the fanned quads close the cube
  EXPECT_EQ(s["charting"]["non_manifold_edges"], 0);
}

TEST_F(BadMesh, ExtremeCoordinates) {
  // Tiny and huge scales, and a mesh far from the origin: built without crashing; the atlas bounds
  // are the input's.
  for (const float scale : {1e-30f, 1e30f}) {
    Mesh m = sphere(5);
    for (glm::vec3& p : m.v) p *= scale;
    const nlohmann::json s = built(write("scaled.obj", objText(m)));
    EXPECT_NEAR(s["bounds"][5].get<double>() / double(scale), 1.0, 0.05) << scale;  // the north pole
    EXPECT_NEAR(s["bounds"][2].get<double>() / double(scale), -1.0, 0.05) << scale;
    fs::remove_all(out_);
  }
  Mesh far = sphere(5, glm::vec3(1e4f, 0, 0));
  const nlohmann::json s = built(write("far.obj", objText(far)));
  EXPECT_NEAR(s["bounds"][5].get<double>(), 1.0, 0.05);
  EXPECT_GT(s["bounds"][0].get<double>(), 1e4 - 1.01);
  EXPECT_LT(s["bounds"][3].get<double>(), 1e4 + 1.01);
}

// The out-of-core path (cell files, --max-memory 64M) on a mesh with every repairable defect, and
// on a binary PLY cut in its faces (found only while the cells are written, after the staging
// directory exists).
TEST_F(BadMesh, OutOfCorePathRepairsAndCleansUp) {
  Mesh m = sphere(132);  // 69168 triangles: above a quarter of 64 MiB at 256 bytes each
  ASSERT_GT(m.f.size() * 256, (64u << 20) / 4);
  const uint32_t nv = uint32_t(m.v.size());
  m.v.push_back({std::numeric_limits<float>::quiet_NaN(), 0, 0});
  m.f.push_back({0, 1, nv});  // non-finite
  m.f.push_back(m.f[100]);    // duplicate
  m.f.push_back({7, 7, 8});   // degenerate
  const size_t valid = m.f.size() - 3;
  // A fin on one edge (non-manifold edge), a triangle touching the south pole only (non-manifold
  // vertex), and a second, small sphere (another component).
  m.v.push_back({3.f, 3.f, 3.f});
  m.f.push_back({m.f[5000][0], m.f[5000][1], uint32_t(m.v.size() - 1)});
  m.v.push_back({0.2f, 0.f, -1.5f});
  m.v.push_back({0.f, 0.2f, -1.5f});
  m.f.push_back({nv - 1, uint32_t(m.v.size() - 1), uint32_t(m.v.size() - 2)});
  append(m, sphere(8, glm::vec3(0, 0, 4), 0.5f));
  const size_t extra = 2 + sphere(8).f.size();
  const std::string ply = plyBinary(m);
  const std::string args = "--max-memory 64M --charts 8 --chart-size 9 --depth 2 --no-fidelity";
  const nlohmann::json s = built(write("big.ply", ply), args);
  EXPECT_EQ(s["charting"]["out_of_core"], true);
  EXPECT_EQ(s["read"]["dropped_non_finite"], 1);
  EXPECT_EQ(s["read"]["dropped_duplicate"], 1);
  EXPECT_EQ(s["read"]["dropped_degenerate"], 1);
  EXPECT_EQ(s["read"]["triangles"], valid + extra);
  EXPECT_EQ(s["charting"]["triangles"], valid + extra);
  EXPECT_GE(s["charting"]["non_manifold_edges"].get<uint64_t>(), 1u);
  EXPECT_GE(s["charting"]["non_manifold_vertices"].get<uint64_t>(), 1u);
  EXPECT_GT(s["charting"]["vertices_split"].get<uint64_t>(), 0u);
  EXPECT_NEAR(s["bounds"][5].get<double>(), 4.5, 0.05);  // the small sphere is charted
  EXPECT_GT(atlasVerticesIn(out_, glm::vec3(-0.6f, -0.6f, 3.4f), glm::vec3(0.6f, 0.6f, 4.6f)), 0u);
  fs::remove_all(out_);
  expectRejected(write("big_cut.ply", ply.substr(0, ply.size() - ply.size() / 5)), {"truncated"}, args);
}

}  // namespace
}  // namespace gimlod
