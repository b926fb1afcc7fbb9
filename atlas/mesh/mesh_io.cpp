// Streaming mesh input with repair counting: format detection and the entry points. The readers
// of each format are in atlas/mesh/mesh_io_ply.cpp, _obj, _off and _stl; what they share is in
// atlas/mesh/mesh_io_internal.h.
#include "atlas/mesh/mesh_io.h"

#include <chrono>
#include <unordered_map>

#include "atlas/mesh/mesh_format.h"
#include "atlas/mesh/mesh_io_internal.h"

namespace gimlod {

namespace fs = std::filesystem;
using namespace meshio;

void MeshBounds::extend(const glm::vec3& p) {
  min = glm::min(min, p);
  max = glm::max(max, p);
}

void MeshBounds::extend(const MeshBounds& b) {
  if (b.empty()) return;
  extend(b.min);
  extend(b.max);
}

const char* meshFormatName(MeshFormat f) {
  switch (f) {
    case MeshFormat::kPly: return "ply";
    case MeshFormat::kObj: return "obj";
    case MeshFormat::kOff: return "off";
    case MeshFormat::kStl: return "stl";
  }
  return "?";
}

namespace {

const char* genericName(MeshFormat f) {
  switch (f) {
    case MeshFormat::kPly: return "PLY";
    case MeshFormat::kObj: return "OBJ";
    case MeshFormat::kOff: return "OFF";
    case MeshFormat::kStl: return "STL";
  }
  return "?";
}

// The format by content (atlas/mesh/mesh_format.h), else by extension. A file whose content
// shows another format than its extension names is read as its content shows, with a warning.
MeshFormat detectFormat(FileBuffer& f, MeshReadStats& stats) {
  const fs::path& path = f.path();
  if (f.size() == 0) fail(path, "empty file");
  f.ensure(std::min<uint64_t>(f.size(), kMeshFormatHeadBytes));
  const std::string_view head(reinterpret_cast<const char*>(f.data()), f.available());
  const std::optional<MeshFormat> content = meshFormatOfContent(head, f.size());
  const std::optional<MeshFormat> ext = meshFormatOfExtension(path);
  if (content) {
    if (ext && *ext != *content)
      warn(stats, std::string("read as ") + genericName(*content) + " by its content, though its extension says ." +
                      meshFormatName(*ext));
    return *content;
  }
  if (ext == MeshFormat::kPly) fail(path, "not a PLY file (it does not start with 'ply')");
  if (ext == MeshFormat::kOff) fail(path, "not an OFF file (it does not start with 'OFF')");
  if (ext) return *ext;  // OBJ and STL name their own problems
  fail(path, "unsupported mesh format (expected PLY, OBJ, OFF or STL content)");
}

void checkOptions(const fs::path& path, const MeshReadOptions& o) {
  if (o.chunkTriangles == 0) fail(path, "bad read options: chunkTriangles must be at least 1");
}

class NullSink : public TriangleSink {
 public:
  void consume(const MeshTriangle*, size_t) override {}
};

// The one reader behind the entry points. va receives the vertex array of indexed formats.
MeshReadStats streamImpl(const fs::path& path, TriangleSink& sink, const MeshReadOptions& o, VertexArray& va,
                         bool verticesOnly) {
  const auto t0 = std::chrono::steady_clock::now();
  checkOptions(path, o);
  FileBuffer f(path);
  MeshReadStats stats;
  stats.info.format = detectFormat(f, stats);
  stats.info.formatName = genericName(stats.info.format);
  Emitter emit(sink, o, stats);
  switch (stats.info.format) {
    case MeshFormat::kPly: readPly(f, emit, va, stats, o, verticesOnly); break;
    case MeshFormat::kOff: readOff(f, emit, va, stats, o, verticesOnly); break;
    case MeshFormat::kObj: readObj(f, emit, va, stats, o); break;
    case MeshFormat::kStl: readStl(f, emit, stats); break;
  }
  if (!verticesOnly) {
    if (stats.faces == 0)
      fail(path, "no faces (" + stats.info.formatName + " with " + std::to_string(stats.vertices) +
                     " vertices and no triangles: a point cloud, not a mesh)");
    emit.begin(stats.info);
    emit.finish();
    if (stats.trianglesOut == 0) {
      // Every triangle was repaired away (e.g. all vertices at one point): nothing to build from.
      std::string why = "no valid triangles: ";
      if (stats.trianglesRead == 0) {
        why += "all " + std::to_string(stats.faces) + " faces have fewer than 3 corners";
      } else {
        why += "all " + std::to_string(stats.trianglesRead) + " triangles were dropped (" +
               std::to_string(stats.droppedNonFinite) + " with a NaN or infinite coordinate, " +
               std::to_string(stats.droppedDegenerate) + " degenerate: repeated vertex or zero " + "area, " +
               std::to_string(stats.droppedDuplicate) + " duplicate)";
      }
      fail(path, why);
    }
  }
  stats.bytesRead = f.offset();
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return stats;
}

}  // namespace

MeshInfo detectMesh(const fs::path& path) {
  FileBuffer f(path, 4096);
  MeshInfo info;
  MeshReadStats unused;
  info.format = detectFormat(f, unused);
  info.formatName = genericName(info.format);
  return info;
}

MeshInfo probeMesh(const fs::path& path, const MeshReadOptions& options) {
  const MeshInfo kind = detectMesh(path);
  VertexArray va;
  NullSink sink;
  if (kind.format == MeshFormat::kPly || kind.format == MeshFormat::kOff)
    return streamImpl(path, sink, options, va, true).info;
  MeshReadOptions o = options;
  o.removeDuplicates = false;
  const MeshReadStats s = streamImpl(path, sink, o, va, false);
  MeshInfo info = s.info;
  info.bounds = s.bounds;  // of the valid triangles
  info.boundsKnown = true;
  info.triangleEstimate = s.trianglesOut;
  return info;
}

MeshReadStats streamMesh(const fs::path& path, TriangleSink& sink, const MeshReadOptions& options) {
  VertexArray va;
  return streamImpl(path, sink, options, va, false);
}

MeshReadStats streamMesh(const fs::path& path, const std::function<void(std::span<const MeshTriangle>)>& consume,
                         const MeshReadOptions& options) {
  class FunctionSink : public TriangleSink {
   public:
    explicit FunctionSink(const std::function<void(std::span<const MeshTriangle>)>& f) : f_(f) {}
    void consume(const MeshTriangle* t, size_t n) override { f_(std::span(t, n)); }

   private:
    const std::function<void(std::span<const MeshTriangle>)>& f_;
  } sink(consume);
  return streamMesh(path, sink, options);
}

IndexedMesh readMesh(const fs::path& path, const MeshReadOptions& options) {
  IndexedMesh mesh;
  VertexArray va;
  struct Weld {
    size_t operator()(const glm::vec3& p) const {
      return mix64((uint64_t{std::bit_cast<uint32_t>(p.x)} << 32 | std::bit_cast<uint32_t>(p.y)) ^
                   mix64(std::bit_cast<uint32_t>(p.z)));
    }
  };
  std::unordered_map<glm::vec3, uint32_t, Weld> welded;
  class Collect : public TriangleSink {
   public:
    Collect(IndexedMesh& m, std::unordered_map<glm::vec3, uint32_t, Weld>& w) : m_(m), w_(w) {}
    void consume(const MeshTriangle* t, size_t n) override {
      for (size_t i = 0; i < n; ++i) {
        std::array<uint32_t, 3> tri = t[i].v;
        if (tri[0] == kNoVertex) {
          for (int k = 0; k < 3; ++k) {
            auto [it, added] = w_.try_emplace(t[i].p[k] + 0.0f, static_cast<uint32_t>(w_.size()));
            if (added) m_.positions.push_back(t[i].p[k]);
            tri[k] = it->second;
          }
        }
        m_.triangles.push_back(tri);
      }
    }

   private:
    IndexedMesh& m_;
    std::unordered_map<glm::vec3, uint32_t, Weld>& w_;
  } sink(mesh, welded);
  mesh.stats = streamImpl(path, sink, options, va, false);
  if (mesh.stats.info.format != MeshFormat::kStl) {
    mesh.positions = std::move(va.pos);
    mesh.colours = std::move(va.col);
  }
  return mesh;
}

}  // namespace gimlod