#include "pipeline/input_kind.h"

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>
#include <string_view>
#include <system_error>

#include "core/atlas_format.h"

namespace fs = std::filesystem;

namespace gimlod {
namespace {

constexpr size_t kHeadBytes = 4096;  // how much of the file the detection reads

bool startsWith(std::string_view s, std::string_view p) { return s.substr(0, p.size()) == p; }

bool isBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }

// The first whitespace-delimited word of the text, after leading blanks and '#' comment lines.
std::string_view firstWord(std::string_view head) {
  size_t b = 0;
  while (b < head.size()) {
    while (b < head.size() && isBlank(head[b])) ++b;
    if (b < head.size() && head[b] == '#') {
      const size_t nl = head.find('\n', b);
      if (nl == std::string_view::npos) return {};
      b = nl + 1;
      continue;
    }
    break;
  }
  size_t e = b;
  while (e < head.size() && !isBlank(head[e])) ++e;
  return head.substr(b, e - b);
}

// "ply" alone on the first line.
bool looksLikePly(std::string_view head) {
  return head.size() >= 4 && startsWith(head, "ply") && (head[3] == '\n' || head[3] == '\r');
}

// OFF and its variants: an optional prefix of S, T, C, N, 4 and n, then "OFF".
bool looksLikeOff(std::string_view head) {
  const std::string_view kw = firstWord(head);
  return kw.size() >= 3 && kw.size() <= 8 && kw.substr(kw.size() - 3) == "OFF" &&
         kw.find_first_not_of("STCN4nOF") == std::string_view::npos;
}

// Binary STL: an 80-byte header and a little-endian triangle count n, in a file of 84 + 50 n bytes.
bool looksLikeBinaryStl(std::string_view head, uint64_t size) {
  if (head.size() < 84) return false;
  const auto* b = reinterpret_cast<const unsigned char*>(head.data()) + 80;
  const uint64_t count = uint64_t(b[0]) | uint64_t(b[1]) << 8 | uint64_t(b[2]) << 16 | uint64_t(b[3]) << 24;
  return size == 84 + 50 * count;
}

// ASCII STL: "solid NAME", then "facet" (or "endsolid": an empty solid).
bool looksLikeAsciiStl(std::string_view head) {
  if (!startsWith(head, "solid")) return false;
  const size_t nl = head.find('\n');
  if (nl == std::string_view::npos) return false;
  const std::string_view rest = firstWord(head.substr(nl + 1));
  return rest == "facet" || rest == "endsolid";
}

// OBJ: text (no NUL byte) with a line starting "v " or "f " (after blanks).
bool looksLikeObj(std::string_view head) {
  if (head.find('\0') != std::string_view::npos) return false;
  size_t b = 0;
  while (b < head.size()) {
    size_t e = head.find('\n', b);
    if (e == std::string_view::npos) e = head.size();
    std::string_view line = head.substr(b, e - b);
    while (!line.empty() && (line.front() == ' ' || line.front() == '\t')) line.remove_prefix(1);
    if (line.size() >= 2 && (line[0] == 'v' || line[0] == 'f') && (line[1] == ' ' || line[1] == '\t')) return true;
    b = e + 1;
  }
  return false;
}

// The kind the extension names; Raster for any other extension.
InputKind kindFromExtension(const fs::path& path) {
  std::string e = path.extension().string();
  for (char& c : e) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (e == ".ply") return InputKind::Ply;
  if (e == ".off") return InputKind::Off;
  if (e == ".stl") return InputKind::Stl;
  if (e == ".obj") return InputKind::Obj;
  return InputKind::Raster;
}

}  // namespace

const char* inputKindName(InputKind kind) {
  switch (kind) {
    case InputKind::Ply: return "PLY";
    case InputKind::Off: return "OFF";
    case InputKind::Stl: return "STL";
    case InputKind::Obj: return "OBJ";
    case InputKind::Raster: return "raster";
  }
  return "?";
}

InputKind detectInputKind(const fs::path& path) {
  const InputKind hint = kindFromExtension(path);
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return hint;  // note: the build's reader names what is wrong
  const uint64_t size = fs::file_size(path, ec);
  if (ec) return hint;
  if (size == 0)
    throw InputError(path.string() + ": empty file (expected a mesh: PLY, OBJ, OFF or STL, or a raster GDAL reads)");
  std::ifstream in(path, std::ios::binary);
  if (!in) return hint;
  std::string head(size_t(std::min<uint64_t>(size, kHeadBytes)), '\0');
  in.read(head.data(), std::streamsize(head.size()));
  head.resize(size_t(in.gcount()));
  if (looksLikePly(head)) return InputKind::Ply;
  if (looksLikeOff(head)) return InputKind::Off;
  if (looksLikeAsciiStl(head)) return InputKind::Stl;
  if (looksLikeBinaryStl(head, size)) return InputKind::Stl;
  if (hint != InputKind::Raster) return hint;  // e.g. "solid" with no facet yet, or a bad file
  if (looksLikeObj(head)) return InputKind::Obj;
  return InputKind::Raster;
}

}  // namespace gimlod
