// OBJ reader.
// Based on: the Wavefront OBJ format description.
#include "atlas/mesh/mesh_io_internal.h"

namespace gimlod::meshio {
namespace {

// "v x y z [w | r g b]" and "f a b c ..." with a = "i", "i/t", "i/t/n" or "i//n"; negative
// indices count back from the last vertex so far. Other statements are ignored.
// note: a face may only use vertices defined before it (true of every common exporter).
class ObjReader : IndexedReader {
 public:
  using IndexedReader::IndexedReader;

  void run() {
    MeshInfo& info = stats_.info;
    info.format = MeshFormat::kObj;
    info.formatName = "OBJ";
    info.triangleEstimate = f_.size() / 48;  // typical bytes per triangle (v and f lines)
    emit_.setVertices(&va_);
    emit_.begin(info);
    std::string_view line, tok;
    FanDecoder fan;
    const uint64_t bytesPerVertex = 16;
    while (f_.nextLine(line)) {
      size_t b = 0;
      while (b < line.size() && isSpace(line[b])) ++b;
      if (b + 1 >= line.size() || !isSpace(line[b + 1])) continue;
      const char kind = line[b];
      if (kind != 'v' && kind != 'f') continue;
      Tokens t{line.substr(b + 2)};
      if (kind == 'v') {
        double c[7];
        int n = 0;
        while (n < 7 && t.next(tok)) {
          if (tok[0] == '#') break;
          if (!parseDouble(tok, c[n]))
            fail(path_, "line " + std::to_string(f_.lineNumber()) + ": bad number " + shown(tok) + cutShort(f_));
          ++n;
        }
        if (n < 3)
          fail(path_, "line " + std::to_string(f_.lineNumber()) + ": vertex needs 3 coordinates" + cutShort(f_));
        if (va_.pos.size() >= kMaxVertices ||
            (o_.maxVertexBytes != 0 && (va_.pos.size() + 1) * bytesPerVertex > o_.maxVertexBytes))
          checkVertexBytes(path_, va_.pos.size() + 1, true, o_, "line " + std::to_string(f_.lineNumber()) + ": ");
        const glm::vec3 p(static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2]));
        if (finite(p))
          info.bounds.extend(p);
        else
          ++stats_.nonFiniteVertices;
        if (n >= 6) {
          if (va_.col.size() < va_.pos.size()) va_.col.resize(va_.pos.size(), kWhite);
          va_.col.push_back(colourFromFloat(c[3], c[4], c[5], 1.0));
          stats_.hasColours = true;
        } else if (!va_.col.empty()) {
          va_.col.push_back(kWhite);
        }
        va_.pos.push_back(p);
        continue;
      }
      // A face.
      const uint64_t face = stats_.faces++;
      fan.start();
      while (t.next(tok)) {
        if (tok[0] == '#') break;
        const char* e = tok.data() + tok.size();
        int64_t idx = 0;
        auto [ptr, ec] = std::from_chars(tok.data(), e, idx);
        if (ec != std::errc() || (ptr != e && *ptr != '/'))
          fail(path_, "line " + std::to_string(f_.lineNumber()) + ": bad face corner " + shown(tok) + cutShort(f_));
        const int64_t n = static_cast<int64_t>(va_.pos.size());
        const int64_t i = idx > 0 ? idx - 1 : n + idx;
        if (idx == 0 || i < 0 || i >= n)
          fail(path_, "line " + std::to_string(f_.lineNumber()) + ": face " + std::to_string(face) +
                          " (counting from 0): vertex index " + std::to_string(idx) + " is out of range (" +
                          std::to_string(n) + " vertices defined before it)");
        fan.push(static_cast<uint32_t>(i), emit_);
      }
      if (fan.corners() < 3)
        ++stats_.shortFaces;
      else if (fan.corners() > 3)
        ++stats_.polygonsFanned;
    }
    if (!va_.col.empty()) va_.col.resize(va_.pos.size(), kWhite);
    stats_.vertices = va_.pos.size();
    stats_.vertexArrayBytes = va_.pos.size() * (va_.col.empty() ? 12 : 16);
    info.vertices = va_.pos.size();
    info.faces = stats_.faces;
    info.hasColours = stats_.hasColours;
  }
};

}  // namespace

void readObj(FileBuffer& f, Emitter& emit, VertexArray& va, MeshReadStats& stats, const MeshReadOptions& o) {
  ObjReader(f, emit, va, stats, o).run();
}

}  // namespace gimlod::meshio
