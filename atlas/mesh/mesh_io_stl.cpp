// STL reader: ASCII and binary.
// Based on: 3D Systems, "StereoLithography Interface Specification" (1989).
#include "atlas/mesh/mesh_io_internal.h"

namespace gimlod::meshio {
namespace {

// Binary if the size matches 84 + 50 n exactly (many binary files also start with "solid"),
// unless the text after "solid" looks like an ASCII STL.
bool stlIsBinary(FileBuffer& f) {
  f.ensure(std::min<uint64_t>(f.size(), 512));
  const size_t n = f.available();
  const char* d = reinterpret_cast<const char*>(f.data());
  const std::string_view head(d, n);
  const bool solid = startsWith(head, "solid");
  if (n >= 84) {
    uint32_t count;
    std::memcpy(&count, d + 80, 4);
    if (std::endian::native == std::endian::big) count = __builtin_bswap32(count);
    if (f.size() == 84 + 50 * uint64_t{count}) {
      if (!solid) return true;
      const size_t nl = head.find('\n');
      if (nl == std::string_view::npos) return true;
      size_t b = nl + 1;
      while (b < n && (isSpace(head[b]) || head[b] == '\n')) ++b;
      const std::string_view rest = head.substr(b);
      return !(startsWith(rest, "facet") || startsWith(rest, "endsolid"));
    }
  }
  return !solid;
}

class StlReader {
 public:
  StlReader(FileBuffer& f, Emitter& emit, MeshReadStats& stats) : f_(f), path_(f.path()), emit_(emit), stats_(stats) {}

  void run() {
    MeshInfo& info = stats_.info;
    info.format = MeshFormat::kStl;
    if (stlIsBinary(f_))
      runBinary();
    else
      runAscii();
  }

 private:
  void runBinary() {
    MeshInfo& info = stats_.info;
    info.formatName = "STL binary";
    if (!f_.ensure(84)) fail(path_, "truncated binary STL: shorter than its 84-byte header");
    uint32_t count;
    std::memcpy(&count, f_.data() + 80, 4);
    if (std::endian::native == std::endian::big) count = __builtin_bswap32(count);
    f_.advance(84);
    const uint64_t need = 84 + 50 * uint64_t{count};
    if (f_.size() < need)
      fail(path_, "truncated binary STL: the header promises " + std::to_string(count) + " facets (" +
                      std::to_string(need) + " bytes) but the file has " + std::to_string(f_.size()) + " bytes");
    if (f_.size() > need) warn(stats_, std::to_string(f_.size() - need) + " bytes after the last STL facet ignored");
    info.faces = count;
    info.triangleEstimate = count;
    emit_.begin(info);
    for (uint32_t i = 0; i < count; ++i) {
      if (!f_.ensure(50)) fail(path_, "truncated binary STL in facet " + std::to_string(i));
      const uint8_t* d = f_.data() + 12;  // skip the normal
      constexpr bool kSwap = std::endian::native == std::endian::big;
      glm::vec3 p[3];
      for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) p[k][c] = std::bit_cast<float>(loadSwapped<uint32_t>(d + 12 * k + 4 * c, kSwap));
      f_.advance(50);
      ++stats_.faces;
      emit_.soup(p[0], p[1], p[2]);
    }
  }

  void runAscii() {
    MeshInfo& info = stats_.info;
    info.formatName = "STL ASCII";
    emit_.begin(info);
    std::string_view line, tok;
    glm::vec3 p[3];
    int corners = 0;
    bool inFacet = false, sawSolid = false;
    while (f_.nextLine(line)) {
      Tokens t{line};
      if (!t.next(tok)) continue;
      const std::string where = "line " + std::to_string(f_.lineNumber());
      // A bad last line without its line break: the file was cut in the middle of it.
      const auto bad = [&](const std::string& what) {
        if (f_.lineUnterminated())
          fail(path_, "truncated ASCII STL: the file ends in the middle of " + where + " (" + what + ")");
        fail(path_, where + ": " + what);
      };
      if (tok == "vertex") {
        if (!inFacet) fail(path_, where + ": vertex outside a facet");
        double c[3];
        for (double& v : c)
          if (!t.next(tok) || !parseDouble(tok, v)) bad("vertex needs 3 coordinates");
        if (corners < 3)
          p[corners] = glm::vec3(static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2]));
        ++corners;
      } else if (tok == "facet") {
        if (inFacet) fail(path_, where + ": 'facet' inside a facet (missing 'endfacet')");
        inFacet = true;
        corners = 0;
      } else if (tok == "endfacet") {
        if (!inFacet) fail(path_, where + ": 'endfacet' without 'facet'");
        if (corners != 3)
          fail(path_, where + ": facet " + std::to_string(stats_.faces) + " has " + std::to_string(corners) +
                          " vertices (STL facets are triangles)");
        inFacet = false;
        ++stats_.faces;
        emit_.soup(p[0], p[1], p[2]);
      } else if (tok == "solid") {
        sawSolid = true;
      } else if (tok == "outer" || tok == "endloop" || tok == "endsolid") {
      } else {
        bad("unexpected " + shown(tok) + " in an ASCII STL");
      }
    }
    if (!sawSolid) fail(path_, "not an ASCII STL (no 'solid')");
    if (inFacet) fail(path_, "truncated ASCII STL: the file ends inside a facet");
    info.faces = stats_.faces;
  }

  FileBuffer& f_;
  fs::path path_;
  Emitter& emit_;
  MeshReadStats& stats_;
};

}  // namespace

void readStl(FileBuffer& f, Emitter& emit, MeshReadStats& stats) { StlReader(f, emit, stats).run(); }

}  // namespace gimlod::meshio
