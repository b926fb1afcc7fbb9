// Tests for gridify: the cells partition the reader's triangles exactly, centroids lie in their
// cells, the buffer budget holds (with a tiny budget forcing many flushes), and failures leave
// no staging directory behind.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "atlas/mesh/gridify.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

fs::path meshPath(const std::string& name) { return test::realData("meshes/" + name); }
bool haveMeshes() { return fs::exists(test::sharedData() / "meshes"); }

void writeFile(const fs::path& p, const std::string& text) { std::ofstream(p, std::ios::binary) << text; }

// A triangle as comparable bits: positions and colours, corners in order.
using TriKey = std::array<uint32_t, 12>;
TriKey key(const MeshTriangle& t) {
  TriKey k;
  for (int c = 0; c < 3; ++c) {
    for (int a = 0; a < 3; ++a) k[c * 3 + a] = std::bit_cast<uint32_t>(t.p[c][a]);
    k[9 + c] = std::bit_cast<uint32_t>(t.c[c]);
  }
  return k;
}

std::vector<TriKey> readerTriangles(const fs::path& mesh) {
  std::vector<TriKey> keys;
  streamMesh(mesh, [&](std::span<const MeshTriangle> t) {
    for (const MeshTriangle& x : t) keys.push_back(key(x));
  });
  std::sort(keys.begin(), keys.end());
  return keys;
}

// Entries of dir that look like a staging directory (".NAME.partial-...").
std::vector<std::string> stagingLeftovers(const fs::path& dir) {
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string n = e.path().filename().string();
    if (n.find(".partial-") != std::string::npos) left.push_back(n);
  }
  return left;
}

// Checks a grid on disk against the reader's output: every triangle in exactly one cell (the
// multisets are equal), each in the cell of its centroid, and that centroid inside the cell box.
void expectGridPartitionsMesh(const fs::path& mesh, const fs::path& grid, const GridifyResult& r) {
  const GridManifest m = readGridManifest(grid);
  EXPECT_EQ(m.triangles, r.triangles);
  EXPECT_EQ(m.cells.size(), r.cells);
  EXPECT_EQ(m.dims, r.manifest.dims);
  std::vector<TriKey> keys;
  uint64_t largest = 0;
  for (const GridCell& c : m.cells) {
    const std::vector<MeshTriangle> tris = readCell(grid, m, c);
    EXPECT_EQ(tris.size(), c.triangles);
    EXPECT_GT(c.triangles, 0u);
    largest = std::max<uint64_t>(largest, tris.size());
    const auto box = m.cellBox(c.coord);
    const double eps = 1e-6 * (m.cellSize[0] + m.cellSize[1] + m.cellSize[2]);
    for (const MeshTriangle& t : tris) {
      keys.push_back(key(t));
      ASSERT_EQ(m.cellOf(t), c.coord);
      for (int a = 0; a < 3; ++a) {
        const double centroid = (double(t.p[0][a]) + t.p[1][a] + t.p[2][a]) / 3.0;
        ASSERT_GE(centroid, box[0][a] - eps) << "cell " << c.id << " axis " << a;
        ASSERT_LE(centroid, box[1][a] + eps) << "cell " << c.id << " axis " << a;
      }
    }
  }
  EXPECT_EQ(largest, r.maxCellTriangles);
  std::sort(keys.begin(), keys.end());
  const std::vector<TriKey> expected = readerTriangles(mesh);
  EXPECT_EQ(keys.size(), expected.size());
  EXPECT_TRUE(keys == expected) << "the cells do not hold exactly the reader's triangles";
}

TEST(Gridify, BunnyCellsPartitionTheReadersTriangles) {
  test::TempDir dir("gridify");
  GridifyOptions o;
  o.targetTrianglesPerCell = 5000;
  const fs::path out = dir.path() / "grid";
  const GridifyResult r = gridify(meshPath("bun_zipper.ply"), out, o);
  EXPECT_EQ(r.triangles, 69451u);
  EXPECT_EQ(r.read.trianglesOut, 69451u);
  EXPECT_FALSE(r.probed);  // PLY: bounds from the vertex array, one read
  EXPECT_GT(r.cells, 4u);
  // The grid is sized for about 5,000 triangles per non-empty cell: no cell is wildly over.
  EXPECT_LE(r.maxCellTriangles, 5u * 5000u);
  EXPECT_LE(r.peakBufferedBytes, r.bufferBudgetBytes);
  EXPECT_EQ(r.manifest.recordBytes, 36u);
  expectGridPartitionsMesh(meshPath("bun_zipper.ply"), out, r);
  EXPECT_TRUE(stagingLeftovers(dir.path()).empty());
  EXPECT_FALSE(fs::exists(out / "cells" / "cell_00000000.bin.tmp"));
  for (const auto& e : fs::directory_iterator(out / "cells")) EXPECT_EQ(e.path().extension(), ".bin") << e.path();
}

TEST(Gridify, TinyBufferBudgetForcesManyFlushesAndStaysUnderIt) {
  test::TempDir dir("gridify");
  GridifyOptions o;
  o.maxMemoryBytes = 64ull << 20;
  o.bufferFraction = 1.0 / 1024;  // a 64 KiB budget for ~2.5 MB of triangles
  o.targetTrianglesPerCell = 2000;
  o.read.chunkTriangles = 512;
  const fs::path out = dir.path() / "grid";
  const GridifyResult r = gridify(meshPath("bun_zipper.ply"), out, o);
  EXPECT_EQ(r.bufferBudgetBytes, 64u << 10);
  EXPECT_LE(r.peakBufferedBytes, r.bufferBudgetBytes);
  EXPECT_GT(r.flushRounds, 20u);
  EXPECT_GT(r.cellWrites, r.cells);  // cells were appended to more than once
  EXPECT_LE(r.peakTrackedBytes, o.maxMemoryBytes);
  expectGridPartitionsMesh(meshPath("bun_zipper.ply"), out, r);
}

TEST(Gridify, ColoursAndBigEndianInputSurviveTheCells) {
  GIMLOD_NEED_SHARED_DATA(haveMeshes());
  test::TempDir dir("gridify");
  GridifyOptions o;
  o.targetTrianglesPerCell = 20000;
  const fs::path out = dir.path() / "grid";
  const GridifyResult r = gridify(meshPath("horse.ply"), out, o);
  EXPECT_TRUE(r.manifest.hasColours);
  EXPECT_EQ(r.manifest.recordBytes, 48u);
  EXPECT_EQ(r.triangles, 96966u);
  expectGridPartitionsMesh(meshPath("horse.ply"), out, r);
}

TEST(Gridify, ObjAndStlUseABoundsPrePass) {
  GIMLOD_NEED_SHARED_DATA(haveMeshes());
  test::TempDir dir("gridify");
  GridifyOptions o;
  o.targetTrianglesPerCell = 10000;
  const GridifyResult r = gridify(meshPath("armadillo.obj"), dir.path() / "obj", o);
  EXPECT_TRUE(r.probed);
  EXPECT_EQ(r.triangles, 86482u);
  expectGridPartitionsMesh(meshPath("armadillo.obj"), dir.path() / "obj", r);

  // The same mesh as a binary STL.
  const IndexedMesh m = readMesh(meshPath("armadillo.obj"));
  std::string stl(80, ' ');
  const uint32_t n = static_cast<uint32_t>(m.triangles.size());
  stl.append(reinterpret_cast<const char*>(&n), 4);
  for (const auto& t : m.triangles) {
    const float zero[3] = {0, 0, 0};
    stl.append(reinterpret_cast<const char*>(zero), 12);
    for (uint32_t v : t) stl.append(reinterpret_cast<const char*>(&m.positions[v]), 12);
    stl.append(2, '\0');
  }
  const fs::path stlPath = dir.path() / "armadillo.stl";
  writeFile(stlPath, stl);
  const GridifyResult rs = gridify(stlPath, dir.path() / "stl", o);
  EXPECT_TRUE(rs.probed);
  EXPECT_EQ(rs.triangles, 86482u);
  EXPECT_EQ(rs.manifest.dims, r.manifest.dims);
  expectGridPartitionsMesh(stlPath, dir.path() / "stl", rs);
}

TEST(Gridify, ReplacesAnEarlierGridButNotOtherDirectories) {
  GIMLOD_NEED_SHARED_DATA(haveMeshes());
  test::TempDir dir("gridify");
  GridifyOptions o;
  o.targetTrianglesPerCell = 20000;
  const fs::path out = dir.path() / "grid";
  gridify(meshPath("bun_zipper.ply"), out, o);
  const GridifyResult r = gridify(meshPath("horse.ply"), out, o);
  EXPECT_EQ(readGridManifest(out).triangles, r.triangles);
  EXPECT_TRUE(stagingLeftovers(dir.path()).empty());

  const fs::path other = dir.path() / "precious";
  fs::create_directory(other);
  writeFile(other / "keep.txt", "mine");
  EXPECT_THROW(gridify(meshPath("horse.ply"), other, o), InputError);
  EXPECT_TRUE(fs::exists(other / "keep.txt"));
  EXPECT_TRUE(stagingLeftovers(dir.path()).empty());
}

TEST(Gridify, FailuresLeaveNoStagingDirectory) {
  test::TempDir dir("gridify");
  const fs::path mesh = dir.path() / "tri.off";
  writeFile(mesh, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  // Output under a regular file.
  const fs::path file = dir.path() / "a_file";
  writeFile(file, "x");
  EXPECT_THROW(gridify(mesh, file / "grid"), InputError);
  EXPECT_THROW(gridify(mesh, file), InputError);
  // Bad input found after the staging directory exists.
  const fs::path bad = dir.path() / "bad.off";
  writeFile(bad, "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 7\n");
  try {
    gridify(bad, dir.path() / "grid");
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("face 1"), std::string::npos) << e.what();
  }
  // Every triangle dropped.
  const fs::path nan = dir.path() / "nan.off";
  writeFile(nan, "OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n");
  try {
    gridify(nan, dir.path() / "grid");
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no valid triangles"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir.path() / "grid"));
  EXPECT_TRUE(stagingLeftovers(dir.path()).empty());
  // And a good run works in the same place.
  const GridifyResult r = gridify(mesh, dir.path() / "grid");
  EXPECT_EQ(r.triangles, 1u);
  EXPECT_EQ(r.cells, 1u);
}

TEST(Gridify, AbsurdOptionsAreInputErrors) {
  test::TempDir dir("gridify");
  const fs::path mesh = dir.path() / "tri.off";
  writeFile(mesh, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  auto expectBad = [&](GridifyOptions o, const std::string& what) {
    try {
      gridify(mesh, dir.path() / "grid", o);
      ADD_FAILURE() << "expected InputError about " << what;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  GridifyOptions o;
  o.targetTrianglesPerCell = 0;
  expectBad(o, "targetTrianglesPerCell");
  o = {};
  o.maxMemoryBytes = 32ull << 20;
  expectBad(o, "maxMemoryBytes");
  o = {};
  o.bufferFraction = 0;
  expectBad(o, "bufferFraction");
  o.bufferFraction = 0.75;
  expectBad(o, "bufferFraction");
  o.bufferFraction = 1e-6;
  expectBad(o, "64 KiB");
  o = {};
  o.read.chunkTriangles = 0;
  expectBad(o, "chunkTriangles");
  o.read.chunkTriangles = 1u << 30;
  expectBad(o, "chunkTriangles");
  EXPECT_FALSE(fs::exists(dir.path() / "grid"));
  EXPECT_TRUE(stagingLeftovers(dir.path()).empty());
}

TEST(Gridify, VertexArrayMustFitAQuarterOfTheCap) {
  test::TempDir dir("gridify");
  // 1.5 million vertices (18 MB of float positions: more than 64 MiB / 4); a sparse file of
  // the right size, so the size check passes and the memory check is the one that fails.
  const fs::path mesh = dir.path() / "big.ply";
  const std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 1500000\nproperty float x\n"
      "property float y\nproperty float z\nelement face 0\n"
      "property list uchar int vertex_indices\nend_header\n";
  writeFile(mesh, header);
  fs::resize_file(mesh, header.size() + 12 * 1500000);
  GridifyOptions o;
  o.maxMemoryBytes = 64ull << 20;
  try {
    gridify(mesh, dir.path() / "grid", o);
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("vertex array of 1500000 vertices"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(stagingLeftovers(dir.path()).empty());
}

TEST(Gridify, ChooseGridDims) {
  MeshBounds cube;
  cube.extend(glm::vec3(0, 0, 0));
  cube.extend(glm::vec3(1, 1, 1));
  EXPECT_EQ(chooseGridDims(cube, 1000, 5000), (std::array<uint32_t, 3>{1, 1, 1}));
  // 100 cells wanted on a surface of estimated area 3: cells of side sqrt(3/100) ~ 0.17.
  EXPECT_EQ(chooseGridDims(cube, 100 * 5000, 5000), (std::array<uint32_t, 3>{6, 6, 6}));
  MeshBounds flat;
  flat.extend(glm::vec3(0, 0, 5));
  flat.extend(glm::vec3(4, 1, 5));
  const auto d = chooseGridDims(flat, 400 * 1000, 1000);  // area 4: cells of side 0.1
  EXPECT_EQ(d, (std::array<uint32_t, 3>{40, 10, 1}));
  MeshBounds line;
  line.extend(glm::vec3(0, 0, 0));
  line.extend(glm::vec3(0, 0, 10));
  EXPECT_EQ(chooseGridDims(line, 10 * 100, 100), (std::array<uint32_t, 3>{1, 1, 10}));
  // Bounded cell counts.
  const auto huge = chooseGridDims(cube, uint64_t{1} << 40, 1, 1u << 20);
  EXPECT_LE(uint64_t{huge[0]} * huge[1] * huge[2], 1u << 20);
  EXPECT_EQ(chooseGridDims(MeshBounds{}, 1000000, 10), (std::array<uint32_t, 3>{1, 1, 1}));
}

TEST(Gridify, ReadCellAndManifestRejectCorruption) {
  test::TempDir dir("gridify");
  const fs::path out = dir.path() / "grid";
  GridifyOptions o;
  o.targetTrianglesPerCell = 20000;
  gridify(meshPath("bun_zipper.ply"), out, o);
  const GridManifest m = readGridManifest(out);
  ASSERT_FALSE(m.cells.empty());
  const fs::path cell = out / m.cells[0].file;
  fs::resize_file(cell, fs::file_size(cell) - 7);
  EXPECT_THROW(readCell(out, m, m.cells[0]), InputError);
  fs::remove(cell);
  EXPECT_THROW(readCell(out, m, m.cells[0]), InputError);
  writeFile(out / kGridManifestName, "{\"format\": \"gimlod-grid\", \"version\": 1}");
  EXPECT_THROW(readGridManifest(out), InputError);
  writeFile(out / kGridManifestName, "not json");
  EXPECT_THROW(readGridManifest(out), InputError);
  EXPECT_THROW(readGridManifest(dir.path() / "nothing"), InputError);
}

}  // namespace
}  // namespace gimlod
