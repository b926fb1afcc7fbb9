// PLY reader: ASCII and binary in both byte orders, faces or triangle strips.
// Based on: Greg Turk, "The PLY Polygon File Format" (1994). Triangle strips are decoded as in
// OpenGL GL_TRIANGLE_STRIP (alternating winding).
#include "atlas/mesh/mesh_io_internal.h"

#include <type_traits>

namespace gimlod::meshio {
namespace {

enum class PlyType : uint8_t { kI8, kU8, kI16, kU16, kI32, kU32, kF32, kF64 };

size_t plySize(PlyType t) {
  switch (t) {
    case PlyType::kI8:
    case PlyType::kU8: return 1;
    case PlyType::kI16:
    case PlyType::kU16: return 2;
    case PlyType::kI32:
    case PlyType::kU32:
    case PlyType::kF32: return 4;
    case PlyType::kF64: return 8;
  }
  return 0;
}

bool plyIsInt(PlyType t) { return t != PlyType::kF32 && t != PlyType::kF64; }

bool plyTypeFromName(std::string_view s, PlyType& t) {
  static const std::pair<const char*, PlyType> kNames[] = {
      {"char", PlyType::kI8},   {"int8", PlyType::kI8},     {"uchar", PlyType::kU8},   {"uint8", PlyType::kU8},
      {"short", PlyType::kI16}, {"int16", PlyType::kI16},   {"ushort", PlyType::kU16}, {"uint16", PlyType::kU16},
      {"int", PlyType::kI32},   {"int32", PlyType::kI32},   {"uint", PlyType::kU32},   {"uint32", PlyType::kU32},
      {"float", PlyType::kF32}, {"float32", PlyType::kF32}, {"double", PlyType::kF64}, {"float64", PlyType::kF64}};
  for (const auto& [n, v] : kNames)
    if (s == n) {
      t = v;
      return true;
    }
  return false;
}

// One PLY scalar as T: double reads every type; int64_t reads the integer types (float index
// types are rejected in the header, and read as 0 here).
template <typename T>
T plyValue(const uint8_t* p, PlyType t, bool swap) {
  switch (t) {
    case PlyType::kI8: return static_cast<int8_t>(p[0]);
    case PlyType::kU8: return p[0];
    case PlyType::kI16: return static_cast<int16_t>(loadSwapped<uint16_t>(p, swap));
    case PlyType::kU16: return loadSwapped<uint16_t>(p, swap);
    case PlyType::kI32: return static_cast<int32_t>(loadSwapped<uint32_t>(p, swap));
    case PlyType::kU32: return loadSwapped<uint32_t>(p, swap);
    case PlyType::kF32:
      if constexpr (std::is_floating_point_v<T>) return std::bit_cast<float>(loadSwapped<uint32_t>(p, swap));
      return 0;
    case PlyType::kF64:
      if constexpr (std::is_floating_point_v<T>) return std::bit_cast<double>(loadSwapped<uint64_t>(p, swap));
      return 0;
  }
  return 0;
}

double plyScalar(const uint8_t* p, PlyType t, bool swap) { return plyValue<double>(p, t, swap); }
int64_t plyInt(const uint8_t* p, PlyType t, bool swap) { return plyValue<int64_t>(p, t, swap); }

struct PlyProp {
  std::string name;
  PlyType type = PlyType::kF32;
  bool list = false;
  PlyType countType = PlyType::kU8;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProp> props;
  // Role of this element.
  enum Kind { kOther, kVertex, kFace, kStrips } kind = kOther;
  int indexProp = -1;  // the vertex index list of faces / strips
};

struct PlyHeader {
  enum Encoding { kAscii, kLittle, kBig } encoding = kAscii;
  std::vector<PlyElement> elements;
};

// Minimum body bytes of an element instance (binary: fixed parts; ASCII: "0 " per value).
uint64_t plyMinInstanceBytes(const PlyElement& e, bool ascii) {
  uint64_t n = 0;
  for (const PlyProp& p : e.props) n += ascii ? 2 : plySize(p.list ? p.countType : p.type);
  return n;
}

PlyHeader readPlyHeader(FileBuffer& f) {
  const fs::path& path = f.path();
  std::string_view line;
  if (!f.nextLine(line) || line != "ply") fail(path, "not a PLY file (the first line is not 'ply')");
  PlyHeader h;
  bool haveFormat = false, done = false;
  while (!done) {
    if (f.offset() > (uint64_t{1} << 20)) fail(path, "bad PLY header: no 'end_header' in the first MiB");
    if (!f.nextLine(line)) fail(path, "bad PLY header: the file ends before 'end_header'");
    if (f.lineUnterminated() && line != "end_header")
      fail(path, "bad PLY header: the file ends before 'end_header', in the middle of header line " +
                     std::to_string(f.lineNumber()) + " (truncated)");
    const std::string where = "PLY header line " + std::to_string(f.lineNumber());
    Tokens t{line};
    std::string_view kw, a, b, c, d;
    if (!t.next(kw)) continue;
    if (kw == "comment" || kw == "obj_info") continue;
    if (kw == "end_header") {
      done = true;
    } else if (kw == "format") {
      if (!t.next(a) || !t.next(b)) fail(path, where + ": bad format line");
      if (a == "ascii")
        h.encoding = PlyHeader::kAscii;
      else if (a == "binary_little_endian")
        h.encoding = PlyHeader::kLittle;
      else if (a == "binary_big_endian")
        h.encoding = PlyHeader::kBig;
      else
        fail(path, where + ": unsupported PLY format " + shown(a));
      if (b != "1.0" && b != "1") fail(path, where + ": unsupported PLY version " + shown(b));
      haveFormat = true;
    } else if (kw == "element") {
      int64_t n = -1;
      if (!t.next(a) || !t.next(b)) fail(path, where + ": bad element line (want 'element NAME COUNT')");
      if (!parseInt(b, n) || n < 0) {
        const bool digits = !b.empty() && b.find_first_not_of("0123456789") == std::string_view::npos;
        fail(path, where + ": bad element line (want 'element NAME COUNT'): the count " + shown(b) +
                       (digits ? " is too large" : " is not a non-negative integer"));
      }
      PlyElement e;
      e.name = std::string(a);
      e.count = static_cast<uint64_t>(n);
      h.elements.push_back(std::move(e));
    } else if (kw == "property") {
      if (h.elements.empty()) fail(path, where + ": property before any element");
      PlyProp p;
      if (!t.next(a)) fail(path, where + ": bad property line");
      if (a == "list") {
        if (!t.next(b) || !t.next(c) || !t.next(d)) fail(path, where + ": bad list property line");
        p.list = true;
        if (!plyTypeFromName(b, p.countType)) fail(path, where + ": unknown PLY property type " + shown(b));
        if (!plyTypeFromName(c, p.type)) fail(path, where + ": unknown PLY property type " + shown(c));
        if (!plyIsInt(p.countType)) fail(path, where + ": list count type " + shown(b) + " is not an integer type");
        p.name = std::string(d);
      } else {
        if (!plyTypeFromName(a, p.type)) fail(path, where + ": unknown PLY property type " + shown(a));
        if (!t.next(b)) fail(path, where + ": property without a name");
        p.name = std::string(b);
      }
      h.elements.back().props.push_back(std::move(p));
    } else {
      fail(path, where + ": unknown PLY header keyword " + shown(kw));
    }
  }
  if (!haveFormat) fail(path, "bad PLY header: no 'format' line");

  // Roles, order, and a size check before anything is allocated.
  int vertexAt = -1, firstFaceAt = -1;
  for (size_t i = 0; i < h.elements.size(); ++i) {
    PlyElement& e = h.elements[i];
    if (e.name == "vertex") {
      if (vertexAt >= 0) fail(path, "bad PLY header: two vertex elements");
      e.kind = PlyElement::kVertex;
      vertexAt = static_cast<int>(i);
      for (const char* axis : {"x", "y", "z"}) {
        auto it = std::find_if(e.props.begin(), e.props.end(), [&](const PlyProp& p) { return p.name == axis; });
        if (it == e.props.end()) fail(path, std::string("PLY vertex element has no '") + axis + "'");
        if (it->list) fail(path, std::string("PLY vertex property '") + axis + "' is a list");
      }
    } else if (e.name == "face" || e.name == "tristrips") {
      e.kind = e.name == "face" ? PlyElement::kFace : PlyElement::kStrips;
      for (size_t k = 0; k < e.props.size(); ++k)
        if (e.props[k].name == "vertex_indices" || (e.kind == PlyElement::kFace && e.props[k].name == "vertex_index"))
          e.indexProp = static_cast<int>(k);
      if (e.indexProp < 0) fail(path, "PLY element '" + e.name + "' has no 'vertex_indices' property");
      const PlyProp& ip = e.props[static_cast<size_t>(e.indexProp)];
      if (!ip.list || !plyIsInt(ip.type))
        fail(path, "PLY property '" + e.name + "." + ip.name + "' must be a list of integers");
      if (firstFaceAt < 0) firstFaceAt = static_cast<int>(i);
    }
  }
  if (vertexAt < 0) fail(path, "PLY file has no vertex element");
  if (firstFaceAt < 0) fail(path, "PLY file has no face or tristrips element (a point cloud, not a mesh)");
  if (firstFaceAt < vertexAt) fail(path, "PLY faces come before the vertices (not supported: faces are streamed)");

  const bool ascii = h.encoding == PlyHeader::kAscii;
  const uint64_t body = f.remaining();
  uint64_t need = 0;
  for (const PlyElement& e : h.elements) {
    const uint64_t per = plyMinInstanceBytes(e, ascii);
    if (per != 0 && e.count > (body - std::min(need, body)) / per + 1)
      fail(path, "the header declares " + std::to_string(e.count) + " '" + e.name + "' elements, needing at least " +
                     std::to_string(e.count) + " x " + std::to_string(per) + " bytes, but only " +
                     std::to_string(body) + " bytes follow the header (truncated or corrupt file)");
    need += e.count * per;
  }
  if (need > body + (ascii ? 1 : 0))
    fail(path, "truncated: the header's elements need at least " + std::to_string(need) + " bytes but only " +
                   std::to_string(body) + " follow the header");
  return h;
}

std::string plyFormatName(const PlyHeader& h) {
  switch (h.encoding) {
    case PlyHeader::kAscii: return "PLY ASCII";
    case PlyHeader::kLittle: return "PLY binary little-endian";
    case PlyHeader::kBig: return "PLY binary big-endian";
  }
  return "PLY";
}

struct PlyVertexLayout {
  int x = -1, y = -1, z = -1, r = -1, g = -1, b = -1, a = -1;
  bool colours() const { return r >= 0 && g >= 0 && b >= 0; }
};

PlyVertexLayout plyVertexLayout(const PlyElement& e) {
  PlyVertexLayout l;
  for (size_t i = 0; i < e.props.size(); ++i) {
    const std::string& n = e.props[i].name;
    if (e.props[i].list) continue;
    const int k = static_cast<int>(i);
    if (n == "x")
      l.x = k;
    else if (n == "y")
      l.y = k;
    else if (n == "z")
      l.z = k;
    else if (n == "red" || n == "diffuse_red" || n == "r")
      l.r = k;
    else if (n == "green" || n == "diffuse_green" || n == "g")
      l.g = k;
    else if (n == "blue" || n == "diffuse_blue" || n == "b")
      l.b = k;
    else if (n == "alpha" || n == "diffuse_alpha" || n == "a")
      l.a = k;
  }
  return l;
}

glm::u8vec4 plyColour(const double* v, const PlyElement& e, const PlyVertexLayout& l) {
  const bool isFloat = !plyIsInt(e.props[static_cast<size_t>(l.r)].type);
  const bool wide = e.props[static_cast<size_t>(l.r)].type == PlyType::kU16 ||
                    e.props[static_cast<size_t>(l.r)].type == PlyType::kI16;
  const double scale = wide ? 1.0 / 257.0 : 1.0;
  const double alpha = l.a >= 0 ? v[l.a] : (isFloat ? 1.0 : 255.0 / scale);
  if (isFloat) return colourFromFloat(v[l.r], v[l.g], v[l.b], alpha);
  return colourFromInt(v[l.r] * scale, v[l.g] * scale, v[l.b] * scale, alpha * scale);
}

class PlyReader : IndexedReader {
 public:
  PlyReader(FileBuffer& f, Emitter& emit, VertexArray& va, MeshReadStats& stats, const MeshReadOptions& o)
      : IndexedReader(f, emit, va, stats, o), tr_(f) {}

  // Reads the header and the vertex element; with verticesOnly, stops there.
  void run(bool verticesOnly) {
    h_ = readPlyHeader(f_);
    ascii_ = h_.encoding == PlyHeader::kAscii;
    swap_ = (h_.encoding == PlyHeader::kBig) != (std::endian::native == std::endian::big);
    MeshInfo& info = stats_.info;
    info.format = MeshFormat::kPly;
    info.formatName = plyFormatName(h_);
    for (const PlyElement& e : h_.elements) {
      if (e.kind == PlyElement::kVertex) {
        info.vertices = e.count;
        info.hasColours = plyVertexLayout(e).colours();
      } else if (e.kind == PlyElement::kFace) {
        info.faces += e.count;
        info.triangleEstimate += e.count;
      } else if (e.kind == PlyElement::kStrips) {
        info.faces += e.count;
        info.triangleEstimate += 2 * info.vertices;  // Euler: a closed mesh has ~2V triangles
      }
    }
    bool begun = false;
    for (size_t i = 0; i < h_.elements.size(); ++i) {
      const PlyElement& e = h_.elements[i];
      if (e.kind == PlyElement::kVertex) {
        readVertices(e);
        if (verticesOnly) return;
      } else if (e.kind == PlyElement::kFace || e.kind == PlyElement::kStrips) {
        if (!begun) {
          emit_.begin(info);
          begun = true;
        }
        readFaces(e);
      } else {
        skipElement(e);
      }
    }
    checkTrailing();
  }

 private:
  std::string elementWhere(const PlyElement& e, uint64_t i) const {
    return "'" + e.name + "' element " + std::to_string(i);
  }
  [[noreturn]] void truncated(const PlyElement& e, uint64_t i) {
    fail(path_, "truncated: the file ends in " + elementWhere(e, i) + " of " + std::to_string(e.count) +
                    " (the header promises " + std::to_string(e.count) + ")");
  }
  [[noreturn]] void badToken(const PlyElement& e, uint64_t i, std::string_view tok) {
    fail(path_, "line " + std::to_string(f_.lineNumber()) + ": bad value " + shown(tok) + " in " + elementWhere(e, i));
  }

  // ASCII: next token as a number (truncated file if none).
  double asciiNumber(const PlyElement& e, uint64_t i, TokenReader& tr) {
    std::string_view tok;
    double v;
    if (!tr.next(tok)) truncated(e, i);
    if (!parseDouble(tok, v)) badToken(e, i, tok);
    return v;
  }
  int64_t asciiInt(const PlyElement& e, uint64_t i, TokenReader& tr) {
    std::string_view tok;
    int64_t v;
    if (!tr.next(tok)) truncated(e, i);
    if (!parseInt(tok, v)) {
      double d;
      if (!parseDouble(tok, d) || d != std::floor(d) || std::abs(d) > 9.0e15) badToken(e, i, tok);
      v = static_cast<int64_t>(d);
    }
    return v;
  }

  void readVertices(const PlyElement& e) {
    const PlyVertexLayout l = plyVertexLayout(e);
    const bool colours = l.colours();
    checkVertexBytes(path_, e.count, colours, o_);
    va_.pos.resize(e.count);
    if (colours) va_.col.resize(e.count);
    stats_.vertices = e.count;
    stats_.hasColours = colours;
    stats_.vertexArrayBytes = e.count * (colours ? 16 : 12);
    std::vector<double> v(e.props.size(), 0.0);
    const bool fixed = std::none_of(e.props.begin(), e.props.end(), [](const PlyProp& p) { return p.list; });
    std::vector<size_t> offs(e.props.size());
    size_t record = 0;
    for (size_t k = 0; k < e.props.size(); ++k) {
      offs[k] = record;
      record += plySize(e.props[k].type);
    }
    MeshBounds& bounds = stats_.info.bounds;
    for (uint64_t i = 0; i < e.count; ++i) {
      if (ascii_) {
        for (size_t k = 0; k < e.props.size(); ++k) {
          if (e.props[k].list) {
            const int64_t n = asciiInt(e, i, tr_);
            for (int64_t j = 0; j < n; ++j) asciiNumber(e, i, tr_);
          } else {
            v[k] = asciiNumber(e, i, tr_);
          }
        }
      } else if (fixed) {
        if (!f_.ensure(record)) truncated(e, i);
        const uint8_t* p = f_.data();
        v[l.x] = plyScalar(p + offs[l.x], e.props[l.x].type, swap_);
        v[l.y] = plyScalar(p + offs[l.y], e.props[l.y].type, swap_);
        v[l.z] = plyScalar(p + offs[l.z], e.props[l.z].type, swap_);
        if (colours) {
          for (int k : {l.r, l.g, l.b, l.a})
            if (k >= 0) v[k] = plyScalar(p + offs[k], e.props[k].type, swap_);
        }
        f_.advance(record);
      } else {
        for (size_t k = 0; k < e.props.size(); ++k) {
          const PlyProp& p = e.props[k];
          if (p.list) {
            if (!f_.ensure(plySize(p.countType))) truncated(e, i);
            const int64_t n = plyInt(f_.data(), p.countType, swap_);
            f_.advance(plySize(p.countType));
            if (n < 0 || static_cast<uint64_t>(n) > f_.remaining() / plySize(p.type) ||
                !f_.skip(static_cast<uint64_t>(n) * plySize(p.type)))
              truncated(e, i);
          } else {
            if (!f_.ensure(plySize(p.type))) truncated(e, i);
            v[k] = plyScalar(f_.data(), p.type, swap_);
            f_.advance(plySize(p.type));
          }
        }
      }
      const glm::vec3 pos(static_cast<float>(v[l.x]), static_cast<float>(v[l.y]), static_cast<float>(v[l.z]));
      va_.pos[i] = pos;
      if (finite(pos))
        bounds.extend(pos);
      else
        ++stats_.nonFiniteVertices;
      if (colours) va_.col[i] = plyColour(v.data(), e, l);
    }
    stats_.info.boundsKnown = true;
    emit_.setVertices(&va_);
  }

  uint32_t checkedIndex(int64_t idx, const PlyElement& e, uint64_t i) {
    if (idx < 0 || static_cast<uint64_t>(idx) >= va_.pos.size())
      fail(path_, elementWhere(e, i) + " (counting from 0): vertex index " + std::to_string(idx) +
                      " is out of range (" + std::to_string(va_.pos.size()) + " vertices)");
    return static_cast<uint32_t>(idx);
  }

  void pushIndex(int64_t idx, const PlyElement& e, uint64_t i) {
    if (e.kind == PlyElement::kFace) {
      fan_.push(checkedIndex(idx, e, i), emit_);
    } else if (idx == -1) {
      strip_.restart();
    } else if (strip_.push(checkedIndex(idx, e, i), emit_)) {
      ++stats_.strips;
    }
  }

  void endList(const PlyElement& e) {
    if (e.kind == PlyElement::kFace) {
      if (fan_.corners() < 3)
        ++stats_.shortFaces;
      else if (fan_.corners() > 3)
        ++stats_.polygonsFanned;
    }
  }

  void readFaces(const PlyElement& e) {
    for (uint64_t i = 0; i < e.count; ++i) {
      ++stats_.faces;
      for (size_t k = 0; k < e.props.size(); ++k) {
        const PlyProp& p = e.props[k];
        const bool isIndex = static_cast<int>(k) == e.indexProp;
        if (isIndex) {
          fan_.start();
          strip_.restart();
        }
        if (ascii_) {
          if (!p.list) {
            asciiNumber(e, i, tr_);
            continue;
          }
          const int64_t n = asciiInt(e, i, tr_);
          if (n < 0) fail(path_, elementWhere(e, i) + ": negative list length");
          for (int64_t j = 0; j < n; ++j) {
            if (isIndex)
              pushIndex(asciiInt(e, i, tr_), e, i);
            else
              asciiNumber(e, i, tr_);
          }
        } else {
          if (!p.list) {
            if (!f_.skip(plySize(p.type))) truncated(e, i);
            continue;
          }
          const size_t cs = plySize(p.countType), es = plySize(p.type);
          if (!f_.ensure(cs)) truncated(e, i);
          const int64_t n = plyInt(f_.data(), p.countType, swap_);
          f_.advance(cs);
          if (n < 0) fail(path_, elementWhere(e, i) + ": negative list length");
          const uint64_t bytes = static_cast<uint64_t>(n) * es;
          if (bytes > f_.remaining()) truncated(e, i);
          if (!isIndex) {
            f_.skip(bytes);
          } else if (bytes <= f_.capacity() / 2) {
            f_.ensure(static_cast<size_t>(bytes));
            const uint8_t* d = f_.data();
            for (int64_t j = 0; j < n; ++j) pushIndex(plyInt(d + j * es, p.type, swap_), e, i);
            f_.advance(static_cast<size_t>(bytes));
          } else {
            for (int64_t j = 0; j < n; ++j) {
              if (!f_.ensure(es)) truncated(e, i);
              pushIndex(plyInt(f_.data(), p.type, swap_), e, i);
              f_.advance(es);
            }
          }
        }
        if (isIndex) endList(e);
      }
    }
  }

  void skipElement(const PlyElement& e) {
    // An element without properties takes no bytes, whatever its count; a binary element of
    // fixed-size records is skipped in one step, so a huge count is a truncated file at once.
    if (e.props.empty()) {
      if (e.count > 0) warn(stats_, "PLY element '" + e.name + "' ignored");
      return;
    }
    if (!ascii_ && std::none_of(e.props.begin(), e.props.end(), [](const PlyProp& p) { return p.list; })) {
      uint64_t record = 0;
      for (const PlyProp& p : e.props) record += plySize(p.type);
      if (e.count > f_.remaining() / record || !f_.skip(e.count * record))
        truncated(e, std::min(e.count, f_.remaining() / record));
      if (e.count > 0) warn(stats_, "PLY element '" + e.name + "' ignored");
      return;
    }
    for (uint64_t i = 0; i < e.count; ++i) {
      for (const PlyProp& p : e.props) {
        if (ascii_) {
          if (p.list) {
            const int64_t n = asciiInt(e, i, tr_);
            for (int64_t j = 0; j < n; ++j) asciiNumber(e, i, tr_);
          } else {
            asciiNumber(e, i, tr_);
          }
        } else if (p.list) {
          if (!f_.ensure(plySize(p.countType))) truncated(e, i);
          const int64_t n = plyInt(f_.data(), p.countType, swap_);
          f_.advance(plySize(p.countType));
          if (n < 0 || static_cast<uint64_t>(n) > f_.remaining() / plySize(p.type) ||
              !f_.skip(static_cast<uint64_t>(n) * plySize(p.type)))
            truncated(e, i);
        } else if (!f_.skip(plySize(p.type))) {
          truncated(e, i);
        }
      }
    }
    if (e.count > 0) warn(stats_, "PLY element '" + e.name + "' ignored");
  }

  void checkTrailing() {
    if (ascii_) {
      std::string_view tok;
      if (tr_.next(tok)) warn(stats_, "text after the last PLY element ignored");
    } else if (f_.remaining() > 0) {
      warn(stats_, std::to_string(f_.remaining()) + " bytes after the last PLY element ignored");
    }
  }

  PlyHeader h_;
  bool ascii_ = false, swap_ = false;
  TokenReader tr_;
  FanDecoder fan_;
  StripDecoder strip_;
};

}  // namespace

void readPly(FileBuffer& f, Emitter& emit, VertexArray& va, MeshReadStats& stats, const MeshReadOptions& o,
             bool verticesOnly) {
  PlyReader(f, emit, va, stats, o).run(verticesOnly);
}

}  // namespace gimlod::meshio
