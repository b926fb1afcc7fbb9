// Tests for the streaming mesh readers: every format and variant on small hand-made files, every
// kind of bad input, and invariants on the real meshes in ../shared/data/meshes.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include "atlas/mesh/mesh_io.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;
using Tri = std::array<uint32_t, 3>;

fs::path meshPath(const std::string& name) { return test::realData("meshes/" + name); }
bool haveMeshes() { return fs::exists(test::sharedData() / "meshes"); }

void writeFile(const fs::path& p, const std::string& text) { std::ofstream(p, std::ios::binary) << text; }
void writeFile(const fs::path& p, const std::vector<uint8_t>& bytes) {
  std::ofstream(p, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

// Little- or big-endian byte writer for binary PLY and STL.
struct Bytes {
  bool big = false;
  std::vector<uint8_t> b;
  void text(const std::string& s) { b.insert(b.end(), s.begin(), s.end()); }
  template <typename T>
  void put(T v) {
    auto a = std::bit_cast<std::array<uint8_t, sizeof(T)>>(v);
    if (big != (std::endian::native == std::endian::big)) std::reverse(a.begin(), a.end());
    b.insert(b.end(), a.begin(), a.end());
  }
};

// Expects an InputError whose message names the file and contains every fragment.
template <typename F>
void expectInputError(F&& f, const fs::path& file, std::initializer_list<std::string> fragments) {
  try {
    f();
    ADD_FAILURE() << "expected InputError for " << file;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(file.string()), std::string::npos) << msg;
    for (const std::string& s : fragments) EXPECT_NE(msg.find(s), std::string::npos) << msg;
  }
}

void expectReadError(const fs::path& file, std::initializer_list<std::string> fragments,
                     const MeshReadOptions& o = {}) {
  expectInputError([&] { readMesh(file, o); }, file, fragments);
}

uint64_t dropped(const MeshReadStats& s) { return s.droppedNonFinite + s.droppedDegenerate + s.droppedDuplicate; }

// A square pyramid: quad base (0 3 2 1), four triangular sides; closed, outward winding.
// Vertex i has colour (10i, 20i, 30i).
const float kPyramid[5][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5f, 0.5f, 1}};
const std::vector<Tri> kPyramidTris = {{0, 3, 2}, {0, 2, 1}, {0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}};

std::string pyramidAsciiPly() {
  std::string s =
      "ply\nformat ascii 1.0\ncomment hand-made\nelement vertex 5\nproperty float x\n"
      "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
      "property uchar blue\nelement face 5\nproperty list uchar int vertex_indices\nend_header\n";
  for (int i = 0; i < 5; ++i)
    s += std::to_string(kPyramid[i][0]) + " " + std::to_string(kPyramid[i][1]) + " " + std::to_string(kPyramid[i][2]) +
         " " + std::to_string(10 * i) + " " + std::to_string(20 * i) + " " + std::to_string(30 * i) + "\n";
  s += "4 0 3 2 1\n3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 4\n";
  return s;
}

// Binary pyramid with unusual types: double positions, float colours, an extra vertex list,
// an "edge" element, and an extra face property before the index list.
std::vector<uint8_t> pyramidBinaryPly(bool big) {
  Bytes w;
  w.big = big;
  w.text(std::string("ply\nformat ") + (big ? "binary_big_endian" : "binary_little_endian") +
         " 1.0\nelement vertex 5\nproperty double x\nproperty double y\nproperty double z\n"
         "property list uchar short junk\nproperty float red\nproperty float green\n"
         "property float blue\nelement edge 1\nproperty int vertex1\nproperty int vertex2\n"
         "element face 5\nproperty ushort flags\nproperty list uint8 uint32 vertex_indices\n"
         "end_header\n");
  for (int i = 0; i < 5; ++i) {
    for (int k = 0; k < 3; ++k) w.put<double>(kPyramid[i][k]);
    w.put<uint8_t>(2);
    w.put<int16_t>(-7);
    w.put<int16_t>(1234);
    w.put<float>(10.f * i / 255.f);
    w.put<float>(20.f * i / 255.f);
    w.put<float>(30.f * i / 255.f);
  }
  w.put<int32_t>(0);
  w.put<int32_t>(1);
  const std::vector<std::vector<uint32_t>> faces = {{0, 3, 2, 1}, {0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}};
  for (const auto& f : faces) {
    w.put<uint16_t>(0xBEEF);
    w.put<uint8_t>(static_cast<uint8_t>(f.size()));
    for (uint32_t i : f) w.put<uint32_t>(i);
  }
  return w.b;
}

void expectPyramid(const IndexedMesh& m, bool colours) {
  ASSERT_EQ(m.positions.size(), 5u);
  for (int i = 0; i < 5; ++i)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(m.positions[i][k], kPyramid[i][k]) << i << " " << k;
  EXPECT_EQ(m.triangles, kPyramidTris);
  EXPECT_EQ(m.stats.trianglesRead, 6u);
  EXPECT_EQ(m.stats.trianglesOut, 6u);
  EXPECT_EQ(m.stats.polygonsFanned, 1u);
  EXPECT_EQ(m.stats.faces, 5u);
  EXPECT_EQ(m.stats.hasColours, colours);
  if (colours) {
    ASSERT_EQ(m.colours.size(), 5u);
    for (int i = 0; i < 5; ++i) EXPECT_EQ(m.colours[i], glm::u8vec4(10 * i, 20 * i, 30 * i, 255)) << i;
  } else {
    EXPECT_TRUE(m.colours.empty());
  }
}

// Directed edges used by more than one triangle: each one means two neighbouring triangles
// disagree on orientation (or the edge is non-manifold). Also counts directed edges without a
// reverse (boundary edges) and undirected edges.
uint64_t repeatedDirectedEdges(const std::vector<Tri>& tris, uint64_t* boundaryEdges = nullptr,
                               uint64_t* undirectedEdges = nullptr) {
  std::vector<uint64_t> directed;
  directed.reserve(tris.size() * 3);
  for (const Tri& t : tris)
    for (int k = 0; k < 3; ++k) directed.push_back(uint64_t{t[k]} << 32 | t[(k + 1) % 3]);
  std::sort(directed.begin(), directed.end());
  uint64_t repeated = 0, boundary = 0, undirected = 0;
  for (size_t i = 0; i < directed.size(); ++i) {
    if (i > 0 && directed[i] == directed[i - 1]) {
      ++repeated;
      continue;
    }
    const uint64_t a = directed[i] >> 32, b = directed[i] & 0xffffffffu;
    const bool twin = std::binary_search(directed.begin(), directed.end(), b << 32 | a);
    if (!twin) ++boundary;
    if (!twin || a < b) ++undirected;
  }
  if (boundaryEdges) *boundaryEdges = boundary;
  if (undirectedEdges) *undirectedEdges = undirected;
  return repeated;
}

// ---- formats ------------------------------------------------------------------------------------

TEST(MeshIoFormats, PlyAsciiWithColoursAndQuad) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "pyramid.ply";
  writeFile(f, pyramidAsciiPly());
  const IndexedMesh m = readMesh(f);
  expectPyramid(m, true);
  EXPECT_EQ(m.stats.info.formatName, "PLY ASCII");
  EXPECT_EQ(m.stats.bounds.min, glm::vec3(0, 0, 0));
  EXPECT_EQ(m.stats.bounds.max, glm::vec3(1, 1, 1));
  EXPECT_TRUE(m.stats.warnings.empty());
}

TEST(MeshIoFormats, PlyBinaryBothEndiansWithExtraElementsAndProperties) {
  test::TempDir dir("mesh-io");
  for (bool big : {false, true}) {
    const fs::path f = dir.path() / (big ? "be.ply" : "le.ply");
    writeFile(f, pyramidBinaryPly(big));
    const IndexedMesh m = readMesh(f);
    SCOPED_TRACE(f.string());
    expectPyramid(m, true);
    EXPECT_EQ(m.stats.info.formatName, big ? "PLY binary big-endian" : "PLY binary little-endian");
    ASSERT_EQ(m.stats.warnings.size(), 1u);  // the edge element is ignored, and said so
    EXPECT_NE(m.stats.warnings[0].find("edge"), std::string::npos);
  }
}

TEST(MeshIoFormats, PlyTriangleStripsAlternateWindingAndRestart) {
  test::TempDir dir("mesh-io");
  // A 2x1 grid of quads as one strip 0 1 2 3 4 5, then -1 and a second strip 6 6 7 8 whose
  // repeated first index gives one degenerate triangle (as strip joins do), then a final -1.
  //  1---3---5       8
  //  | / | / |       | .
  //  0---2---4       6---7   (diagonals 1-2 and 3-4)
  Bytes w;
  w.text(
      "ply\nformat binary_little_endian 1.0\nelement vertex 9\nproperty float x\n"
      "property float y\nproperty float z\nelement tristrips 1\n"
      "property list int int vertex_indices\nend_header\n");
  const float xy[9][2] = {{0, 0}, {0, 1}, {1, 0}, {1, 1}, {2, 0}, {2, 1}, {5, 0}, {6, 0}, {5, 1}};
  for (const auto& p : xy) {
    w.put<float>(p[0]);
    w.put<float>(p[1]);
    w.put<float>(0);
  }
  const std::vector<int32_t> strip = {0, 1, 2, 3, 4, 5, -1, 6, 6, 7, 8, -1};
  w.put<int32_t>(static_cast<int32_t>(strip.size()));
  for (int32_t i : strip) w.put<int32_t>(i);
  const fs::path f = dir.path() / "strips.ply";
  writeFile(f, w.b);
  const IndexedMesh m = readMesh(f);
  EXPECT_EQ(m.stats.strips, 2u);
  EXPECT_EQ(m.stats.trianglesRead, 4u + 2u);
  EXPECT_EQ(m.stats.droppedStripDegenerate, 1u);
  EXPECT_EQ(m.stats.droppedDegenerate, 1u);
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {2, 1, 3}, {2, 3, 4}, {4, 3, 5}, {7, 6, 8}}));
  // Every triangle has the orientation of the first (all in the z = 0 plane).
  auto signedArea = [&](const Tri& t) {
    const glm::vec3 a = m.positions[t[0]], b = m.positions[t[1]], c = m.positions[t[2]];
    return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
  };
  const float first = signedArea(m.triangles[0]);
  EXPECT_NE(first, 0.f);
  for (size_t i = 0; i < m.triangles.size(); ++i)
    EXPECT_GT(signedArea(m.triangles[i]) * first, 0.f) << "strip triangle " << i;
  EXPECT_EQ(repeatedDirectedEdges(m.triangles), 0u);
}

TEST(MeshIoFormats, ObjNegativeAndSlashedIndicesAndPolygons) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "pyramid.obj";
  std::string s = "# hand-made\nmtllib none.mtl\no pyramid\n";
  for (const auto& p : kPyramid)
    s += "v " + std::to_string(p[0]) + " " + std::to_string(p[1]) + " " + std::to_string(p[2]) + "\n";
  s += "vt 0 0\nvn 0 0 1\ng sides\ns off\nusemtl none\n";
  s += "f -5/1/1 -2/1/1 -3/1/1 -4/1/1\n";  // the base quad 0 3 2 1, by negative indices
  s += "f 1//1 2//1 5//1\n";
  s += "f 2/1 3/1 5/1\r\n";  // CRLF line ending
  s += "  f\t3 4 5   # trailing comment\n";
  s += "f 4/1/1 1/1/1 -1/1/1\n";
  s += "l 1 2\np 3\n";
  writeFile(f, s);
  const IndexedMesh m = readMesh(f);
  expectPyramid(m, false);
  EXPECT_EQ(m.stats.info.formatName, "OBJ");
}

TEST(MeshIoFormats, ObjVertexColours) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "c.obj";
  writeFile(f, "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n");
  const IndexedMesh m = readMesh(f);
  ASSERT_EQ(m.colours.size(), 3u);
  EXPECT_EQ(m.colours[0], glm::u8vec4(255, 0, 0, 255));
  EXPECT_EQ(m.colours[2], glm::u8vec4(0, 0, 255, 255));
  EXPECT_TRUE(m.stats.hasColours);
}

TEST(MeshIoFormats, OffWithCommentsQuadAndColours) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "pyramid.off";
  std::string s = "OFF\n# a comment\n\n5 5 8\n";
  for (const auto& p : kPyramid)
    s += std::to_string(p[0]) + " " + std::to_string(p[1]) + " " + std::to_string(p[2]) + "\n";
  s += "4 0 3 2 1\n3 0 1 4 255 0 0\n3 1 2 4\n3 2 3 4  # face comment\n3 3 0 4\n";
  writeFile(f, s);
  expectPyramid(readMesh(f), false);

  const fs::path c = dir.path() / "pyramid_c.off";
  s = "COFF 5 5 0\n";
  for (int i = 0; i < 5; ++i)
    s += std::to_string(kPyramid[i][0]) + " " + std::to_string(kPyramid[i][1]) + " " + std::to_string(kPyramid[i][2]) +
         " " + std::to_string(10 * i) + " " + std::to_string(20 * i) + " " + std::to_string(30 * i) + " 255\n";
  s += "4 0 3 2 1\n3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 4\n";
  writeFile(c, s);
  expectPyramid(readMesh(c), true);
}

std::vector<std::array<glm::vec3, 3>> pyramidSoup() {
  std::vector<std::array<glm::vec3, 3>> soup;
  for (const Tri& t : kPyramidTris) {
    std::array<glm::vec3, 3> s;
    for (int k = 0; k < 3; ++k) s[k] = glm::vec3(kPyramid[t[k]][0], kPyramid[t[k]][1], kPyramid[t[k]][2]);
    soup.push_back(s);
  }
  return soup;
}

std::string asciiStl(const std::vector<std::array<glm::vec3, 3>>& soup) {
  std::string s = "solid test\n";
  for (const auto& t : soup) {
    s += "  facet normal 0 0 0\n    outer loop\n";
    for (const glm::vec3& p : t)
      s += "      vertex " + std::to_string(p.x) + " " + std::to_string(p.y) + " " + std::to_string(p.z) + "\n";
    s += "    endloop\n  endfacet\n";
  }
  return s + "endsolid test\n";
}

std::vector<uint8_t> binaryStl(const std::vector<std::array<glm::vec3, 3>>& soup,
                               const std::string& header = "binary") {
  Bytes w;
  std::string h = header;
  h.resize(80, ' ');
  w.text(h);
  w.put<uint32_t>(static_cast<uint32_t>(soup.size()));
  for (const auto& t : soup) {
    for (int k = 0; k < 3; ++k) w.put<float>(0);
    for (const glm::vec3& p : t) {
      w.put<float>(p.x);
      w.put<float>(p.y);
      w.put<float>(p.z);
    }
    w.put<uint16_t>(0);
  }
  return w.b;
}

TEST(MeshIoFormats, StlAsciiAndBinaryWeldToTheSameMesh) {
  test::TempDir dir("mesh-io");
  const fs::path a = dir.path() / "p_ascii.stl", b = dir.path() / "p_bin.stl", c = dir.path() / "p_solid_header.stl";
  writeFile(a, asciiStl(pyramidSoup()));
  writeFile(b, binaryStl(pyramidSoup()));
  writeFile(c, binaryStl(pyramidSoup(), "solid but binary"));
  for (const fs::path& f : {a, b, c}) {
    SCOPED_TRACE(f.string());
    const IndexedMesh m = readMesh(f);
    EXPECT_EQ(m.stats.info.formatName, f == a ? "STL ASCII" : "STL binary");
    EXPECT_EQ(m.positions.size(), 5u);  // welded by exact position
    ASSERT_EQ(m.triangles.size(), 6u);
    EXPECT_EQ(repeatedDirectedEdges(m.triangles), 0u);
    uint64_t boundary = 1;
    repeatedDirectedEdges(m.triangles, &boundary);
    EXPECT_EQ(boundary, 0u);
    for (size_t i = 0; i < 6; ++i)
      for (int k = 0; k < 3; ++k) EXPECT_EQ(m.positions[m.triangles[i][k]], pyramidSoup()[i][k]);
  }
}

TEST(MeshIoFormats, DetectsByMagicWhateverTheExtension) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "pyramid.mesh";
  writeFile(f, pyramidAsciiPly());
  EXPECT_EQ(detectMesh(f).format, MeshFormat::kPly);
  expectPyramid(readMesh(f), true);
  const fs::path o = dir.path() / "pyramid.data";
  writeFile(o, "OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  EXPECT_EQ(readMesh(o).triangles.size(), 1u);
  const fs::path x = dir.path() / "what.xyz";
  writeFile(x, "0 0 0\n1 1 1\n");
  expectReadError(x, {"unsupported mesh format"});
}

// Content decides over a misleading extension: an OBJ, a binary STL without "solid" and an ASCII
// STL under names that say otherwise are read as what they are, with a warning naming both.
TEST(MeshIoFormats, ContentWinsOverAMisleadingExtension) {
  test::TempDir dir("mesh-io");
  const fs::path obj = dir.path() / "scan.ply", bin = dir.path() / "part.obj", txt = dir.path() / "part.off";
  writeFile(obj, "# exported\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  writeFile(bin, binaryStl(pyramidSoup()));
  writeFile(txt, asciiStl(pyramidSoup()));
  const IndexedMesh a = readMesh(obj);
  EXPECT_EQ(a.stats.info.format, MeshFormat::kObj);
  EXPECT_EQ(a.triangles.size(), 1u);
  ASSERT_EQ(a.stats.warnings.size(), 1u);
  EXPECT_NE(a.stats.warnings[0].find("read as OBJ by its content, though its extension says .ply"), std::string::npos)
      << a.stats.warnings[0];
  for (const fs::path& f : {bin, txt}) {
    SCOPED_TRACE(f.string());
    const IndexedMesh m = readMesh(f);
    EXPECT_EQ(m.stats.info.format, MeshFormat::kStl);
    EXPECT_EQ(m.triangles.size(), 6u);
    ASSERT_FALSE(m.stats.warnings.empty());
    EXPECT_NE(m.stats.warnings[0].find("read as STL"), std::string::npos) << m.stats.warnings[0];
  }
  EXPECT_EQ(detectMesh(bin).format, MeshFormat::kStl);
  EXPECT_EQ(detectMesh(obj).format, MeshFormat::kObj);
}

TEST(MeshIoFormats, StreamsInChunksWithInfoFirst) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "pyramid.ply";
  writeFile(f, pyramidAsciiPly());
  struct Sink : TriangleSink {
    std::vector<size_t> chunks;
    std::vector<MeshTriangle> all;
    bool begun = false, beganFirst = true;
    MeshInfo info;
    void begin(const MeshInfo& i) override {
      begun = true;
      info = i;
    }
    void consume(const MeshTriangle* t, size_t n) override {
      beganFirst = beganFirst && begun;
      chunks.push_back(n);
      all.insert(all.end(), t, t + n);
    }
  } sink;
  MeshReadOptions o;
  o.chunkTriangles = 4;
  const MeshReadStats s = streamMesh(f, sink, o);
  EXPECT_TRUE(sink.beganFirst);
  EXPECT_TRUE(sink.info.boundsKnown);
  EXPECT_EQ(sink.info.vertices, 5u);
  EXPECT_EQ(sink.chunks, (std::vector<size_t>{4, 2}));
  ASSERT_EQ(sink.all.size(), 6u);
  EXPECT_EQ(sink.all[5].v, (Tri{3, 0, 4}));
  EXPECT_EQ(sink.all[5].p[2], glm::vec3(0.5f, 0.5f, 1));
  EXPECT_EQ(sink.all[5].c[0], glm::u8vec4(30, 60, 90, 255));
  EXPECT_EQ(s.trianglesOut, 6u);
  const MeshInfo probe = probeMesh(f);
  EXPECT_TRUE(probe.boundsKnown);
  EXPECT_EQ(probe.bounds.max, glm::vec3(1, 1, 1));
}

// ---- repairs ------------------------------------------------------------------------------------

TEST(MeshIoRepair, NonFiniteCoordinatesDropTheirTriangles) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "nan.ply";
  // Vertex 4 is NaN and vertex 5 infinite; 3 triangles use them.
  writeFile(f,
            "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
            "property float z\nelement face 4\nproperty list uchar int vertex_indices\n"
            "end_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\nnan 0 0\n0 inf 1e999\n"
            "3 0 1 2\n3 1 3 4\n3 4 5 0\n3 2 5 1\n");
  const IndexedMesh m = readMesh(f);
  EXPECT_EQ(m.stats.nonFiniteVertices, 2u);
  EXPECT_EQ(m.stats.droppedNonFinite, 3u);
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}}));
  EXPECT_EQ(m.stats.info.bounds.max, glm::vec3(1, 1, 0));  // finite vertices only

  const fs::path s = dir.path() / "nan.stl";
  auto soup = pyramidSoup();
  soup[2][1].y = std::numeric_limits<float>::quiet_NaN();
  writeFile(s, binaryStl(soup));
  EXPECT_EQ(readMesh(s).stats.droppedNonFinite, 1u);

  const fs::path o = dir.path() / "nan.obj";
  writeFile(o, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv NaN 0 0\nf 1 2 3\nf 1 2 4\n");
  EXPECT_EQ(readMesh(o).stats.droppedNonFinite, 1u);
}

TEST(MeshIoRepair, DegenerateAndDuplicateTrianglesAreDroppedAndCounted) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "bad.off";
  // 0 1 2 is kept; repeated index; collinear (zero area); coincident positions (3 == 0);
  // duplicates of 0 1 2 rotated and flipped.
  writeFile(f,
            "OFF\n5 7 0\n0 0 0\n1 0 0\n0 1 0\n0 0 0\n2 0 0\n"
            "3 0 1 2\n3 0 0 1\n3 0 1 4\n3 3 0 1\n3 1 2 0\n3 2 1 0\n3 0 2 4\n");
  const IndexedMesh m = readMesh(f);
  EXPECT_EQ(m.stats.trianglesRead, 7u);
  EXPECT_EQ(m.stats.droppedDegenerate, 3u);
  EXPECT_EQ(m.stats.droppedDuplicate, 2u);
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {0, 2, 4}}));
  EXPECT_EQ(m.stats.trianglesOut + dropped(m.stats), m.stats.trianglesRead);
  EXPECT_TRUE(m.stats.duplicateCheckComplete);

  MeshReadOptions keep;
  keep.removeDuplicates = false;
  EXPECT_EQ(readMesh(f, keep).triangles.size(), 4u);

  // STL duplicates are found by position.
  const fs::path s = dir.path() / "dup.stl";
  auto soup = pyramidSoup();
  soup.push_back({soup[1][2], soup[1][0], soup[1][1]});
  soup.push_back({soup[0][0], soup[0][0], soup[0][1]});
  writeFile(s, binaryStl(soup));
  const IndexedMesh ms = readMesh(s);
  EXPECT_EQ(ms.stats.droppedDuplicate, 1u);
  EXPECT_EQ(ms.stats.droppedDegenerate, 1u);
  EXPECT_EQ(ms.triangles.size(), 6u);
}

TEST(MeshIoRepair, DuplicatesFarApartAcrossChunksKeepTheFirstCopyInOrder) {
  test::TempDir dir("mesh-io");
  // A strip of 100 triangles, then the same 100 in reverse order with rotated corners.
  const fs::path f = dir.path() / "dups.off";
  std::string s = "OFF\n102 200 0\n";
  for (int i = 0; i < 102; ++i)
    s += std::to_string(i / 2) + " " + std::to_string(i % 2) + " " + std::to_string(i % 3) + "\n";
  std::vector<Tri> first;
  auto face = [](uint32_t a, uint32_t b, uint32_t c) {
    return "3 " + std::to_string(a) + " " + std::to_string(b) + " " + std::to_string(c) + "\n";
  };
  for (uint32_t i = 0; i < 100; ++i) {
    first.push_back({i, i + 1, i + 2});
    s += face(i, i + 1, i + 2);
  }
  for (uint32_t i = 100; i-- > 0;) s += face(i + 2, i, i + 1);
  writeFile(f, s);
  MeshReadOptions o;
  o.chunkTriangles = 7;
  std::vector<Tri> got;
  std::vector<size_t> sizes;
  const MeshReadStats st = streamMesh(
      f,
      [&](std::span<const MeshTriangle> t) {
        sizes.push_back(t.size());
        for (const MeshTriangle& x : t) got.push_back(x.v);
      },
      o);
  EXPECT_EQ(st.droppedDuplicate, 100u);
  EXPECT_EQ(st.droppedDegenerate, 0u);
  EXPECT_EQ(got, first);
  ASSERT_FALSE(sizes.empty());
  for (size_t i = 0; i + 1 < sizes.size(); ++i) EXPECT_EQ(sizes[i], 7u);
  EXPECT_EQ(sizes.back(), 100u % 7);
}

TEST(MeshIoRepair, DuplicateSetBoundIsReportedNotFatal) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "pyramid.ply";
  writeFile(f, pyramidAsciiPly());
  MeshReadOptions o;
  o.duplicateSetBytes = 64;  // room for 2 triangles
  const IndexedMesh m = readMesh(f, o);
  EXPECT_EQ(m.triangles.size(), 6u);
  EXPECT_FALSE(m.stats.duplicateCheckComplete);
  EXPECT_FALSE(m.stats.warnings.empty());
}

TEST(MeshIoRepair, NonManifoldAndSeveralComponentsReadAsIs) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "nm.obj";
  // Three triangles on edge 1-2 (non-manifold edge), a bowtie vertex, and a far component.
  writeFile(f,
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 0 0 1\nv -1 -1 0\nv -1 0 0\n"
            "v 10 10 10\nv 11 10 10\nv 10 11 10\n"
            "f 1 2 3\nf 2 4 3\nf 2 3 5\nf 1 6 7\nf 8 9 10\n");
  const IndexedMesh m = readMesh(f);
  EXPECT_EQ(m.triangles.size(), 5u);
  EXPECT_EQ(dropped(m.stats), 0u);
}

// ---- bad input ----------------------------------------------------------------------------------

TEST(MeshIoBadInput, EmptyFilesOfEveryFormat) {
  test::TempDir dir("mesh-io");
  for (const char* name : {"e.ply", "e.obj", "e.off", "e.stl", "e.bin"}) {
    const fs::path f = dir.path() / name;
    writeFile(f, std::string());
    expectReadError(f, {"empty file"});
  }
  expectReadError(dir.path() / "missing.ply", {"cannot open"});
  expectReadError(dir.path(), {"not a regular file"});
}

TEST(MeshIoBadInput, TruncatedBinaryPly) {
  test::TempDir dir("mesh-io");
  const std::vector<uint8_t> full = pyramidBinaryPly(false);
  const size_t header = std::string(full.begin(), full.end()).find("end_header\n") + 11;
  // Cut in the vertices (caught by the size check before reading) and in the faces.
  for (size_t keep : {header + 10, header + 5 * 40, full.size() - 3}) {
    const fs::path f = dir.path() / ("cut" + std::to_string(keep) + ".ply");
    writeFile(f, std::vector<uint8_t>(full.begin(), full.begin() + static_cast<long>(keep)));
    SCOPED_TRACE(keep);
    expectReadError(f, {"truncated"});
  }
  const fs::path f = dir.path() / "cut_face.ply";
  writeFile(f, std::vector<uint8_t>(full.begin(), full.end() - 3));
  expectReadError(f, {"'face' element 4"});
}

TEST(MeshIoBadInput, TruncatedTextFormats) {
  test::TempDir dir("mesh-io");
  const fs::path p = dir.path() / "t.ply";
  std::string ply = pyramidAsciiPly();
  writeFile(p, ply.substr(0, ply.size() - 8));
  expectReadError(p, {"truncated"});
  const fs::path o = dir.path() / "t.off";
  writeFile(o, "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  expectReadError(o, {"truncated", "1 of 2 faces"});
  const fs::path s = dir.path() / "t.stl";
  const std::string stl = asciiStl(pyramidSoup());
  writeFile(s, stl.substr(0, stl.find("endloop")));
  expectReadError(s, {"ends inside a facet"});
  const fs::path b = dir.path() / "tb.stl";
  auto bin = binaryStl(pyramidSoup());
  bin.erase(bin.end() - 20, bin.end());
  writeFile(b, bin);
  expectReadError(b, {"truncated binary STL", "6 facets"});
}

TEST(MeshIoBadInput, FaceIndexOutOfRangeNamesTheFace) {
  test::TempDir dir("mesh-io");
  const fs::path p = dir.path() / "oob.ply";
  std::string ply = pyramidAsciiPly();
  ply.replace(ply.find("3 1 2 4"), 7, "3 1 2 9");
  writeFile(p, ply);
  expectReadError(p, {"'face' element 2 (counting from 0)", "index 9", "out of range"});

  std::vector<uint8_t> bin = pyramidBinaryPly(true);
  bin[bin.size() - 1] = 77;  // the last index of the last face
  const fs::path b = dir.path() / "oob_be.ply";
  writeFile(b, bin);
  expectReadError(b, {"'face' element 4 (counting from 0)", "index 77"});

  const fs::path n = dir.path() / "neg.ply";
  ply = pyramidAsciiPly();
  ply.replace(ply.find("3 1 2 4"), 7, "3 1 -2 4");
  writeFile(n, ply);
  expectReadError(n, {"'face' element 2", "index -2"});

  const fs::path o = dir.path() / "oob.off";
  writeFile(o, "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 3\n");
  expectReadError(o, {"face 1 (counting from 0)", "index 3"});

  const fs::path j = dir.path() / "oob.obj";
  writeFile(j, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n");
  expectReadError(j, {"line 5", "face 1 (counting from 0)", "index 4"});
  writeFile(j, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
  expectReadError(j, {"index 0"});
  writeFile(j, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n");
  expectReadError(j, {"index -4"});
  writeFile(j, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n");
  expectReadError(j, {"bad face corner 'x'"});
}

TEST(MeshIoBadInput, BadPlyHeaders) {
  test::TempDir dir("mesh-io");
  const std::string good = pyramidAsciiPly();
  struct Case {
    std::string from, to, expect;
  };
  const std::vector<Case> cases = {
      {"property float x", "property float128 x", "unknown PLY property type 'float128'"},
      {"property list uchar int", "property list uchar quad", "unknown PLY property type 'quad'"},
      {"property list uchar int", "property list float int", "not an integer type"},
      {"property list uchar int vertex_indices", "property list uchar float vertex_indices",
       "must be a list of integers"},
      {"format ascii 1.0", "format binary_middle_endian 1.0", "unsupported PLY format"},
      {"format ascii 1.0", "format ascii 2.0", "unsupported PLY version"},
      {"format ascii 1.0\n", "", "no 'format' line"},
      {"comment hand-made", "frobnicate", "unknown PLY header keyword 'frobnicate'"},
      {"property float z", "property float w", "no 'z'"},
      {"element face 5\nproperty list uchar int vertex_indices\n", "", "no face or tristrips"},
      {"vertex_indices", "corners", "no 'vertex_indices'"},
      {"element vertex 5", "element vertex -5", "bad element line"},
      {"element vertex 5\nproperty float x", "property float x\nelement vertex 5", "property before any element"},
  };
  int i = 0;
  for (const Case& c : cases) {
    std::string text = good;
    const size_t at = text.find(c.from);
    ASSERT_NE(at, std::string::npos) << c.from;
    text.replace(at, c.from.size(), c.to);
    const fs::path f = dir.path() / (std::to_string(i++) + "_header.ply");
    writeFile(f, text);
    SCOPED_TRACE(c.expect);
    expectReadError(f, {c.expect});
  }
  const fs::path order = dir.path() / "order.ply";
  writeFile(order,
            "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n"
            "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            "end_header\n3 0 1 2\n0 0 0\n1 0 0\n0 1 0\n");
  expectReadError(order, {"faces come before the vertices"});
  const fs::path notPly = dir.path() / "not.ply";
  writeFile(notPly, "plyx\nformat ascii 1.0\n");
  expectReadError(notPly, {"not a PLY file"});
  const fs::path open = dir.path() / "open.ply";
  writeFile(open, good.substr(0, good.find("end_header")));
  expectReadError(open, {"ends before 'end_header'"});
  const fs::path endless = dir.path() / "endless.ply";
  std::string comments = "ply\nformat ascii 1.0\n";
  while (comments.size() < (2u << 20)) comments += "comment no end in sight\n";
  writeFile(endless, comments);
  expectReadError(endless, {"no 'end_header'"});
  const fs::path badValue = dir.path() / "value.ply";
  std::string text = good;
  text.replace(text.find("3 0 1 4"), 7, "3 0 one 4");
  writeFile(badValue, text);
  expectReadError(badValue, {"bad value 'one'", "'face' element 1"});
}

TEST(MeshIoBadInput, HugeDeclaredCountsFailBeforeAllocating) {
  test::TempDir dir("mesh-io");
  // 4 billion vertices (48 GB) declared in a file of a few hundred bytes.
  std::string bin =
      std::string(reinterpret_cast<const char*>(pyramidBinaryPly(false).data()), pyramidBinaryPly(false).size());
  bin.replace(bin.find("element vertex 5"), 16, "element vertex 4000000000");
  const fs::path f = dir.path() / "huge.ply";
  writeFile(f, bin);
  expectReadError(f, {"4000000000 'vertex' elements", "bytes follow the header"});
  std::string ascii = pyramidAsciiPly();
  ascii.replace(ascii.find("element face 5"), 14, "element face 9999999999999");
  const fs::path a = dir.path() / "huge_ascii.ply";
  writeFile(a, ascii);
  expectReadError(a, {"'face' elements", "truncated or corrupt"});
  const fs::path o = dir.path() / "huge.off";
  writeFile(o, "OFF\n999999999999 1 0\n0 0 0\n");
  expectReadError(o, {"999999999999 vertices", "truncated or corrupt"});
  // A list length beyond the end of the file.
  std::vector<uint8_t> strips;
  {
    Bytes w;
    w.text(
        "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
        "property float y\nproperty float z\nelement tristrips 1\n"
        "property list int int vertex_indices\nend_header\n");
    for (int k = 0; k < 9; ++k) w.put<float>(float(k % 2));
    w.put<int32_t>(2000000000);
    w.put<int32_t>(0);
    strips = w.b;
  }
  const fs::path s = dir.path() / "long_list.ply";
  writeFile(s, strips);
  expectReadError(s, {"truncated", "'tristrips' element 0"});
}

TEST(MeshIoBadInput, VertexArrayOverItsBound) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "pyramid.ply";
  writeFile(f, pyramidAsciiPly());
  MeshReadOptions o;
  o.maxVertexBytes = 40;
  expectReadError(f, {"vertex array of 5 vertices", "more than the 40 bytes allowed"}, o);
  const fs::path j = dir.path() / "pyramid.obj";
  writeFile(j, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 1\nf 1 2 3\n");
  expectReadError(j, {"line 3", "more than the 40 bytes allowed"}, o);
}

TEST(MeshIoBadInput, UnsupportedVariantsAndJunk) {
  test::TempDir dir("mesh-io");
  const fs::path b = dir.path() / "b.off";
  writeFile(b, "OFF BINARY\n");
  expectReadError(b, {"binary OFF is not supported"});
  const fs::path d = dir.path() / "d.off";
  writeFile(d, "4OFF\n1 0 0\n0 0 0 0\n");
  expectReadError(d, {"unsupported OFF variant '4OFF'"});
  const fs::path n = dir.path() / "n.off";
  writeFile(n, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n5 0 1 2\n");
  expectReadError(n, {"declares 5 corners"});
  const fs::path s = dir.path() / "quad.stl";
  writeFile(s,
            "solid q\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
            "vertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid q\n");
  expectReadError(s, {"has 4 vertices"});
  const fs::path j = dir.path() / "junk.stl";
  writeFile(j, "solid j\nfacet normal 0 0 1\nbanana\n");
  expectReadError(j, {"unexpected 'banana'"});
  // Binary junk without line breaks, named .obj.
  const fs::path o = dir.path() / "junk.obj";
  writeFile(o, std::string(5 << 20, 'x'));
  expectReadError(o, {"longer than"});
  const fs::path p = dir.path() / "points.obj";
  writeFile(p, "v 0 0 0\nv 1 0 0\n");
  expectReadError(p, {"no faces"});
  const fs::path t = dir.path() / "text.obj";
  writeFile(t, "v 0 0 zero\n");
  expectReadError(t, {"line 1", "bad number 'zero'"});
}

TEST(MeshIoBadInput, AbsurdOptions) {
  test::TempDir dir("mesh-io");
  const fs::path f = dir.path() / "pyramid.ply";
  writeFile(f, pyramidAsciiPly());
  MeshReadOptions o;
  o.chunkTriangles = 0;
  expectReadError(f, {"chunkTriangles"}, o);
}

// ---- the real meshes --------------------------------------------------------------------------

struct RealMesh {
  const char* file;
  uint64_t triangles;  // from ../shared/data/README.md
  const char* format;
  bool colours;
  bool closed;
};
// note: the README counts are face records as stored (strips decoded). None of these files has a
// degenerate, duplicate or non-finite triangle, so read == listed with nothing dropped; the test
// asserts out + dropped == listed so that it states the accounting, and dropped == 0.
const RealMesh kRealMeshes[] = {
    {"bun_zipper.ply", 69451, "PLY ASCII", false, false},
    {"igea.ply", 268686, "PLY binary little-endian", false, true},
    {"turbineblade.ply", 199034, "PLY binary little-endian", false, true},
    {"horse.ply", 96966, "PLY binary big-endian", true, true},
    {"armadillo.obj", 86482, "OBJ", false, true},
};

TEST(MeshIoReal, EverySharedMeshReadsWithItsListedTriangleCount) {
  GIMLOD_NEED_SHARED_DATA(haveMeshes());
  for (const RealMesh& r : kRealMeshes) {
    SCOPED_TRACE(r.file);
    const IndexedMesh m = readMesh(meshPath(r.file));
    const MeshReadStats& s = m.stats;
    EXPECT_EQ(s.info.formatName, r.format);
    EXPECT_EQ(s.trianglesRead, r.triangles);
    EXPECT_EQ(s.trianglesOut + dropped(s), r.triangles);
    EXPECT_EQ(dropped(s), 0u);
    EXPECT_EQ(m.triangles.size(), s.trianglesOut);
    EXPECT_EQ(s.hasColours, r.colours);
    EXPECT_EQ(m.colours.size(), r.colours ? m.positions.size() : 0u);
    EXPECT_EQ(s.nonFiniteVertices, 0u);
    EXPECT_FALSE(s.bounds.empty());
    EXPECT_TRUE(s.warnings.empty());
    for (const Tri& t : m.triangles)
      for (uint32_t v : t) ASSERT_LT(v, m.positions.size());
    // Invariant on closed meshes: consistent winding, so every directed edge appears once and
    // has its reverse.
    if (r.closed) {
      uint64_t boundary = 0;
      EXPECT_EQ(repeatedDirectedEdges(m.triangles, &boundary), 0u);
      EXPECT_EQ(boundary, 0u);
    }
  }
}

TEST(MeshIoReal, IgeaStripsDecodeToAConsistentlyOrientedGenusZeroSurface) {
  GIMLOD_NEED_SHARED_DATA(haveMeshes());
  const IndexedMesh m = readMesh(meshPath("igea.ply"));
  EXPECT_EQ(m.stats.faces, 1u);       // one tristrips element instance ...
  EXPECT_EQ(m.stats.strips, 35048u);  // ... holding 35,048 strips separated by -1
  EXPECT_EQ(m.triangles.size(), 268686u);
  uint64_t boundary = 1, edges = 0;
  const uint64_t repeated = repeatedDirectedEdges(m.triangles, &boundary, &edges);
  EXPECT_EQ(repeated, 0u);
  EXPECT_EQ(boundary, 0u);
  // Euler characteristic V - E + F = 2 for a closed genus-0 surface.
  std::vector<bool> used(m.positions.size());
  for (const Tri& t : m.triangles)
    for (uint32_t v : t) used[v] = true;
  const int64_t v = std::count(used.begin(), used.end(), true);
  EXPECT_EQ(v - int64_t(edges) + int64_t(m.triangles.size()), 2);

  // Decoding strips with the same winding for every triangle (the classic mistake) breaks this.
  std::vector<Tri> flipped = m.triangles;
  for (size_t i = 1; i < flipped.size(); i += 2) std::swap(flipped[i][0], flipped[i][1]);
  EXPECT_GT(repeatedDirectedEdges(flipped), 10000u);
}

TEST(MeshIoReal, HorseIsBigEndianWithColoursBunnyIsAscii) {
  GIMLOD_NEED_SHARED_DATA(haveMeshes());
  const MeshInfo horse = probeMesh(meshPath("horse.ply"));
  EXPECT_EQ(horse.formatName, "PLY binary big-endian");
  EXPECT_TRUE(horse.hasColours);
  EXPECT_TRUE(horse.boundsKnown);
  EXPECT_EQ(horse.vertices, 48485u);
  const IndexedMesh h = readMesh(meshPath("horse.ply"));
  // Big-endian floats decoded right: a horse-sized box, not byte-swapped garbage.
  const glm::vec3 ext = h.stats.bounds.max - h.stats.bounds.min;
  for (int k = 0; k < 3; ++k) EXPECT_TRUE(ext[k] > 1e-3f && ext[k] < 1e3f) << ext[k];
  // The first vertex, as decoded independently from the big-endian bytes.
  EXPECT_EQ(h.positions[0], glm::vec3(-0.002022000029683113f, -0.04017850011587143f, -0.0008630002848803997f));
  // Every vertex of this file is coloured (255, 255, 255) after a float "confidence": a wrong
  // record layout would read other bytes.
  for (const glm::u8vec4& c : h.colours) ASSERT_EQ(c, glm::u8vec4(255, 255, 255, 255));
  EXPECT_EQ(probeMesh(meshPath("bun_zipper.ply")).formatName, "PLY ASCII");
}

TEST(MeshIoReal, ChunkedStreamEqualsWholeRead) {
  GIMLOD_NEED_SHARED_DATA(haveMeshes());
  const fs::path f = meshPath("armadillo.obj");
  const IndexedMesh whole = readMesh(f);
  MeshReadOptions o;
  o.chunkTriangles = 1000;
  std::vector<Tri> streamed;
  size_t chunks = 0, largest = 0;
  streamMesh(
      f,
      [&](std::span<const MeshTriangle> t) {
        ++chunks;
        largest = std::max(largest, t.size());
        for (const MeshTriangle& x : t) {
          streamed.push_back(x.v);
          for (int k = 0; k < 3; ++k) ASSERT_EQ(x.p[k], whole.positions[x.v[k]]);
        }
      },
      o);
  EXPECT_EQ(streamed, whole.triangles);
  EXPECT_EQ(chunks, (whole.triangles.size() + 999) / 1000);
  EXPECT_EQ(largest, 1000u);
  const MeshInfo probe = probeMesh(f);  // OBJ: a full pass
  EXPECT_EQ(probe.triangleEstimate, 86482u);
  EXPECT_EQ(probe.bounds.min, whole.stats.bounds.min);
  EXPECT_EQ(probe.bounds.max, whole.stats.bounds.max);
}

}  // namespace
}  // namespace gimlod
