#include "atlas/mesh/mesh_format.h"

#include <cctype>
#include <string>

namespace gimlod {
namespace {

bool startsWith(std::string_view s, std::string_view p) { return s.substr(0, p.size()) == p; }

bool isBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; }

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

bool looksLikePly(std::string_view head) {
  return head.size() >= 4 && startsWith(head, "ply") && (head[3] == '\n' || head[3] == '\r');
}

// OFF and its variants: an optional prefix of S, T, C, N, 4 and n, then "OFF".
bool looksLikeOff(std::string_view head) {
  const std::string_view kw = firstWord(head);
  return kw.size() >= 3 && kw.size() <= 8 && kw.substr(kw.size() - 3) == "OFF" &&
         kw.find_first_not_of("STCN4nOF") == std::string_view::npos;
}

bool looksLikeBinaryStl(std::string_view head, uint64_t size) {
  if (head.size() < 84) return false;
  const auto* b = reinterpret_cast<const unsigned char*>(head.data()) + 80;
  const uint64_t count = uint64_t(b[0]) | uint64_t(b[1]) << 8 | uint64_t(b[2]) << 16 | uint64_t(b[3]) << 24;
  return size == 84 + 50 * count;
}

bool looksLikeAsciiStl(std::string_view head) {
  if (!startsWith(head, "solid")) return false;
  const size_t nl = head.find('\n');
  if (nl == std::string_view::npos) return false;
  const std::string_view rest = firstWord(head.substr(nl + 1));
  return rest == "facet" || rest == "endsolid";
}

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

}  // namespace

std::optional<MeshFormat> meshFormatOfContent(std::string_view head, uint64_t fileSize) {
  if (looksLikePly(head)) return MeshFormat::kPly;
  if (looksLikeOff(head)) return MeshFormat::kOff;
  if (looksLikeAsciiStl(head) || looksLikeBinaryStl(head, fileSize)) return MeshFormat::kStl;
  if (looksLikeObj(head)) return MeshFormat::kObj;
  return std::nullopt;
}

std::optional<MeshFormat> meshFormatOfExtension(const std::filesystem::path& path) {
  std::string e = path.extension().string();
  for (char& c : e) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (e == ".ply") return MeshFormat::kPly;
  if (e == ".obj") return MeshFormat::kObj;
  if (e == ".off") return MeshFormat::kOff;
  if (e == ".stl") return MeshFormat::kStl;
  return std::nullopt;
}

}  // namespace gimlod
