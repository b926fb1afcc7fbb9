// Grid strip generation for the (u,v) grids of paper section 7.3.
#include "runtime/grid_strips.h"

#include <algorithm>

namespace gimlod {

std::vector<uint32_t> buildGridStripIndices(uint32_t res, uint32_t bandQuads) {
  const uint32_t n = 1u << res;
  bandQuads = std::max(1u, std::min(bandQuads, n));
  std::vector<uint32_t> out;
  out.reserve(size_t(n) * (2 * n + 2 * (n / bandQuads + 1) + n / bandQuads + 1));
  for (uint32_t i0 = 0; i0 < n; i0 += bandQuads) {
    const uint32_t i1 = std::min(n, i0 + bandQuads);
    for (uint32_t j = 0; j < n; ++j) {
      if (!out.empty()) out.push_back(kPrimitiveRestartIndex);
      // note: the order (i,j+1), (i,j), (i+1,j+1), (i+1,j), ... makes the edge shared by each
      // quad's two triangles run from (i,j) to (i+1,j+1), the diagonal the error metric assumes.
      for (uint32_t i = i0; i <= i1; ++i) {
        out.push_back(gridVertexIndex(res, i, j + 1));
        out.push_back(gridVertexIndex(res, i, j));
      }
    }
  }
  return out;
}

std::vector<Triangle> expandStrips(std::span<const uint32_t> indices, uint32_t restart) {
  std::vector<Triangle> out;
  size_t stripStart = 0;
  for (size_t k = 0; k <= indices.size(); ++k) {
    if (k < indices.size() && indices[k] != restart) continue;
    for (size_t t = stripStart; t + 2 < k; ++t) {
      const bool odd = ((t - stripStart) & 1) != 0;
      Triangle tri = odd ? Triangle{indices[t + 1], indices[t], indices[t + 2]}
                         : Triangle{indices[t], indices[t + 1], indices[t + 2]};
      if (tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2]) out.push_back(tri);
    }
    stripStart = k + 1;
  }
  return out;
}

std::vector<Triangle> expectedGridTriangles(uint32_t res) {
  const uint32_t n = 1u << res;
  std::vector<Triangle> out;
  out.reserve(size_t(2) * n * n);
  for (uint32_t j = 0; j < n; ++j) {
    for (uint32_t i = 0; i < n; ++i) {
      const uint32_t a = gridVertexIndex(res, i, j), b = gridVertexIndex(res, i + 1, j);
      const uint32_t c = gridVertexIndex(res, i + 1, j + 1), d = gridVertexIndex(res, i, j + 1);
      out.push_back({a, b, c});
      out.push_back({a, c, d});
    }
  }
  return out;
}

}  // namespace gimlod
