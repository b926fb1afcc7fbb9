// OFF reader.
// Based on: the Geomview OFF format description.
#include "atlas/mesh/mesh_io_internal.h"

namespace gimlod::meshio {
namespace {

// Geomview OFF: "[ST][C][N]OFF", counts "nv nf [ne]", then vertex lines
// "x y z [nx ny nz] [r g b [a]] [s t]" and face lines "n i0 .. i(n-1) [colour]". '#' comments.
class OffReader : IndexedReader {
 public:
  using IndexedReader::IndexedReader;

  void run(bool verticesOnly) {
    std::string_view line;
    if (!dataLine(line)) fail(path_, "empty OFF file");
    Tokens t{line};
    std::string_view kw;
    t.next(kw);
    if (kw.size() < 3 || kw.substr(kw.size() - 3) != "OFF")
      fail(path_, "not an OFF file (it does not start with 'OFF')");
    for (char c : kw.substr(0, kw.size() - 3)) {
      if (c == 'C')
        colours_ = true;
      else if (c == 'N')
        normals_ = true;
      else if (c != 'S' && c != 'T')
        fail(path_, "unsupported OFF variant " + shown(kw) + " (4D and nD OFF)");
    }
    std::string_view tok;
    int64_t counts[3] = {-1, -1, 0};
    int got = 0;
    if (t.next(tok)) {
      if (tok == "BINARY") fail(path_, "binary OFF is not supported");
      if (!parseInt(tok, counts[got++])) fail(path_, "bad OFF counts " + shown(tok));
    }
    while (got < 2) {
      if (got == 0 && !dataLine(line)) fail(path_, "truncated: no vertex and face counts");
      if (got == 0) t = Tokens{line};
      while (got < 3 && t.next(tok))
        if (!parseInt(tok, counts[got++])) fail(path_, "bad OFF counts " + shown(tok));
      if (got < 2) fail(path_, "line " + std::to_string(f_.lineNumber()) + ": want 'vertices faces [edges]' counts");
    }
    if (counts[0] < 0 || counts[1] < 0) fail(path_, "negative OFF counts");
    const uint64_t nv = static_cast<uint64_t>(counts[0]), nf = static_cast<uint64_t>(counts[1]);
    // Each vertex line needs at least "0 0 0\n", each face line "0\n".
    const uint64_t body = f_.remaining();
    if (nv > (body + 1) / 6 || nf > (body + 1 - nv * 6) / 2 + 1)
      fail(path_, "the header declares " + std::to_string(nv) + " vertices and " + std::to_string(nf) +
                      " faces but only " + std::to_string(body) + " bytes follow (truncated or corrupt file)");
    MeshInfo& info = stats_.info;
    info.format = MeshFormat::kOff;
    info.formatName = "OFF";
    info.vertices = nv;
    info.faces = nf;
    info.triangleEstimate = nf;
    info.hasColours = colours_;

    checkVertexBytes(path_, nv, colours_, o_);
    va_.pos.resize(nv);
    if (colours_) va_.col.resize(nv);
    stats_.vertices = nv;
    stats_.hasColours = colours_;
    stats_.vertexArrayBytes = nv * (colours_ ? 16 : 12);
    for (uint64_t i = 0; i < nv; ++i) {
      if (!dataLine(line))
        fail(path_, "truncated: the file ends after " + std::to_string(i) + " of " + std::to_string(nv) + " vertices");
      readVertex(line, i);
    }
    info.boundsKnown = true;
    emit_.setVertices(&va_);
    if (verticesOnly) return;
    emit_.begin(info);
    FanDecoder fan;
    for (uint64_t i = 0; i < nf; ++i) {
      if (!dataLine(line))
        fail(path_, "truncated: the file ends after " + std::to_string(i) + " of " + std::to_string(nf) + " faces");
      ++stats_.faces;
      Tokens ft{line};
      int64_t n = -1;
      if (!ft.next(tok) || !parseInt(tok, n) || n < 0)
        fail(path_, "line " + std::to_string(f_.lineNumber()) + ": face " + std::to_string(i) +
                        " (counting from 0) has a bad corner count");
      fan.start();
      for (int64_t j = 0; j < n; ++j) {
        int64_t idx;
        if (!ft.next(tok) || !parseInt(tok, idx))
          fail(path_, "line " + std::to_string(f_.lineNumber()) + ": face " + std::to_string(i) +
                          " (counting from 0) declares " + std::to_string(n) + " corners but does not list them" +
                          cutShort(f_));
        if (idx < 0 || static_cast<uint64_t>(idx) >= nv)
          fail(path_, "line " + std::to_string(f_.lineNumber()) + ": face " + std::to_string(i) +
                          " (counting from 0): vertex index " + std::to_string(idx) + " is out of range (" +
                          std::to_string(nv) + " vertices)");
        fan.push(static_cast<uint32_t>(idx), emit_);
      }
      if (n < 3)
        ++stats_.shortFaces;
      else if (n > 3)
        ++stats_.polygonsFanned;
    }
    if (dataLine(line)) warn(stats_, "text after the last OFF face ignored");
  }

 private:
  // Next line with data, comments removed.
  bool dataLine(std::string_view& line) {
    while (f_.nextLine(line)) {
      const size_t hash = line.find('#');
      if (hash != std::string_view::npos) line = line.substr(0, hash);
      Tokens t{line};
      std::string_view tok;
      if (t.next(tok)) return true;
    }
    return false;
  }

  void readVertex(std::string_view line, uint64_t i) {
    Tokens t{line};
    std::string_view tok;
    double v[3];
    for (double& c : v) {
      if (!t.next(tok) || !parseDouble(tok, c))
        fail(path_, "line " + std::to_string(f_.lineNumber()) + ": vertex " + std::to_string(i) +
                        " needs 3 coordinates" + cutShort(f_));
    }
    const glm::vec3 p(static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2]));
    va_.pos[i] = p;
    if (finite(p))
      stats_.info.bounds.extend(p);
    else
      ++stats_.nonFiniteVertices;
    if (!colours_) return;
    if (normals_)
      for (int k = 0; k < 3; ++k) t.next(tok);
    double c[4] = {1, 1, 1, 1};
    bool isFloat = false;
    int n = 0;
    while (n < 4 && t.next(tok)) {
      if (!parseDouble(tok, c[n])) break;
      if (tok.find_first_of(".eE") != std::string_view::npos) isFloat = true;
      ++n;
    }
    if (n < 3) {
      va_.col[i] = kWhite;
    } else if (isFloat) {
      va_.col[i] = colourFromFloat(c[0], c[1], c[2], n == 4 ? c[3] : 1.0);
    } else {
      va_.col[i] = colourFromInt(c[0], c[1], c[2], n == 4 ? c[3] : 255.0);
    }
  }

  bool colours_ = false, normals_ = false;
};

}  // namespace

void readOff(FileBuffer& f, Emitter& emit, VertexArray& va, MeshReadStats& stats, const MeshReadOptions& o,
             bool verticesOnly) {
  OffReader(f, emit, va, stats, o).run(verticesOnly);
}

}  // namespace gimlod::meshio
