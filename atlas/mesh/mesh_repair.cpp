// Welding and repair of the charting's input: exact-position weld, degenerate and duplicate
// triangles dropped, half-edges paired, non-manifold edges and vertices cut open.
#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <utility>

#include "atlas/mesh/charting_internal.h"
#include "core/union_find.h"

namespace gimlod::charting {

Surface repairWelded(Welder&& w, ChartingStats& st, std::vector<uint32_t>* perTriangle) {
  const char* fn = "buildPatchLayout";
  Surface s;
  std::vector<std::array<uint32_t, 3>> tris = std::move(w.tris);
  st.inputTriangles += tris.size();
  st.inputVertices += w.referenced;
  st.verticesWelded += w.referenced - w.positions.size();
  w.table = PositionWeld(0);  // the table is no longer needed
  // 2. Drop degenerate and duplicate triangles (first one kept). Triangles are bucketed by
  // their smallest vertex (counting sort), so each bucket holds a handful of candidates: O(n)
  // and 4 bytes per triangle, where one global sort of (vertex triple, index) keys would take 16.
  const uint32_t nw = static_cast<uint32_t>(w.positions.size());
  std::vector<uint8_t> keep(tris.size(), 0);
  {
    std::vector<uint32_t> start(size_t{nw} + 1, 0);
    auto sortedOf = [&](uint32_t i) {
      std::array<uint32_t, 3> t = tris[i];
      std::sort(t.begin(), t.end());
      return t;
    };
    for (uint32_t i = 0; i < tris.size(); ++i) {
      const std::array<uint32_t, 3> t = sortedOf(i);
      if (t[0] == t[1] || t[1] == t[2]) {
        ++st.droppedDegenerate;
        continue;
      }
      keep[i] = 1;
      ++start[t[0] + 1];
    }
    for (uint32_t v = 0; v < nw; ++v) start[v + 1] += start[v];
    std::vector<uint32_t> bucket(start[nw]);
    {
      std::vector<uint32_t> fill(start.begin(), start.end() - 1);
      for (uint32_t i = 0; i < tris.size(); ++i)
        if (keep[i]) bucket[fill[sortedOf(i)[0]]++] = i;
    }
    std::vector<std::pair<std::array<uint32_t, 3>, uint32_t>> group;
    for (uint32_t v = 0; v < nw; ++v) {
      const uint32_t b = start[v], e = start[v + 1];
      if (e - b < 2) continue;
      group.clear();
      for (uint32_t k = b; k < e; ++k) group.push_back({sortedOf(bucket[k]), bucket[k]});
      std::sort(group.begin(), group.end());
      for (size_t k = 1; k < group.size(); ++k)
        if (group[k].first == group[k - 1].first) {
          keep[group[k].second] = 0;
          ++st.droppedDuplicate;
        }
    }
  }
  {
    size_t n = 0;
    for (size_t i = 0; i < tris.size(); ++i) {
      if (!keep[i]) continue;
      tris[n] = tris[i];
      if (perTriangle) (*perTriangle)[n] = (*perTriangle)[i];
      ++n;
    }
    tris.resize(n);
    tris.shrink_to_fit();
    if (perTriangle) {
      perTriangle->resize(n);
      perTriangle->shrink_to_fit();
    }
  }
  std::vector<uint8_t>().swap(keep);
  const uint32_t nf = static_cast<uint32_t>(tris.size());
  if (nf == 0) throw InputError(std::string(fn) + ": no triangle left after welding");
  // 3. Pair half-edges by undirected edge: half-edges bucketed by their smaller vertex
  // (counting sort), each bucket ordered by (larger vertex, half-edge), which groups them
  // exactly as a global sort of (edge key, half-edge) would. The buckets are filled a range of
  // vertices at a time, so that the bucket array stays small on large meshes.
  auto org = [&](uint32_t h) { return tris[h / 3][h % 3]; };
  auto dst = [&](uint32_t h) { return tris[h / 3][(h % 3 + 1) % 3]; };
  s.twin.assign(size_t{nf} * 3, kNone);
  std::vector<std::vector<uint32_t>> badGroups;
  {
    std::vector<uint32_t> start(size_t{nw} + 1, 0);
    for (uint32_t h = 0; h < 3 * nf; ++h) ++start[std::min(org(h), dst(h)) + 1];
    for (uint32_t v = 0; v < nw; ++v) start[v + 1] += start[v];
    constexpr uint32_t kRange = uint32_t{1} << 23;  // half-edges (and vertices) per range
    std::vector<uint32_t> he, fill;
    auto far = [&](uint32_t h) { return std::max(org(h), dst(h)); };
    for (uint32_t lo = 0; lo < nw;) {
      uint32_t hi = lo + 1;
      while (hi < nw && hi - lo < kRange && start[hi + 1] - start[lo] <= kRange) ++hi;
      he.resize(start[hi] - start[lo]);
      fill.resize(hi - lo);
      for (uint32_t v = lo; v < hi; ++v) fill[v - lo] = start[v] - start[lo];
      for (uint32_t h = 0; h < 3 * nf; ++h) {  // h ascending in each bucket
        const uint32_t v = std::min(org(h), dst(h));
        if (v >= lo && v < hi) he[fill[v - lo]++] = h;
      }
      for (uint32_t v = lo; v < hi; ++v) {
        const auto b = he.begin() + (start[v] - start[lo]), e = he.begin() + (start[v + 1] - start[lo]);
        std::stable_sort(b, e, [&](uint32_t x, uint32_t y) { return far(x) < far(y); });
        for (auto i = b; i != e;) {
          auto j = i + 1;
          while (j != e && far(*j) == far(*i)) ++j;
          if (j - i == 2 && org(*i) != org(*(i + 1))) {
            s.twin[*i] = *(i + 1);
            s.twin[*(i + 1)] = *i;
          } else if (j - i >= 2) {
            ++st.nonManifoldEdges;
            std::vector<uint32_t> fw, bw, all;
            for (auto k = i; k != j; ++k) {
              const uint32_t h = *k;
              all.push_back(h);
              (org(h) < dst(h) ? fw : bw).push_back(h);
            }
            for (size_t k = 0; k < std::min(fw.size(), bw.size()); ++k) {
              s.twin[fw[k]] = bw[k];
              s.twin[bw[k]] = fw[k];
            }
            badGroups.push_back(std::move(all));
          }
          i = j;
        }
      }
      lo = hi;
    }
  }
  // 4. Split vertices into fans (corners linked across paired edges). Repeat if a split leaves
  // two edges between the same two vertices (a fan closing round a fin): detach that triangle.
  const uint32_t nv0 = nw;
  std::vector<uint32_t> newId, vertexOf;  // corner -> new vertex; new vertex -> welded
  uint64_t splitVertices = 0;
  for (int round = 0;; ++round) {
    {
      UnionFind uf(size_t{nf} * 3);
      for (uint32_t h = 0; h < 3 * nf; ++h) {
        const uint32_t t = s.twin[h];
        if (t == kNone || t < h) continue;
        uf.unite(h, nextHe(t));
        uf.unite(nextHe(h), t);
      }
      newId = std::move(uf.parent);
    }
    // Corners in ascending order: a root (the smallest corner of its fan) gets the fan's vertex
    // id; any other corner's parent is a smaller corner, already replaced by that id.
    std::vector<uint8_t> owned(nv0, 0);
    std::vector<uint8_t> counted(nv0, 0);
    vertexOf.resize(nv0);
    std::iota(vertexOf.begin(), vertexOf.end(), 0u);
    splitVertices = 0;
    uint64_t nonManifoldVertices = 0;
    for (uint32_t c = 0; c < 3 * nf; ++c) {
      if (newId[c] != c) {
        newId[c] = newId[newId[c]];
        continue;
      }
      const uint32_t v = org(c);
      if (!owned[v]) {
        owned[v] = 1;
        newId[c] = v;
      } else {
        newId[c] = static_cast<uint32_t>(vertexOf.size());
        vertexOf.push_back(v);
        ++splitVertices;
        if (!counted[v]) {
          counted[v] = 1;
          ++nonManifoldVertices;
        }
      }
    }
    bool changed = false;
    for (const auto& g : badGroups) {
      for (size_t a = 0; a < g.size(); ++a) {
        for (size_t b = 0; b < g.size(); ++b) {
          const uint32_t ha = g[a], hb = g[b];
          if (a == b || s.twin[ha] == hb) continue;
          const uint32_t a0 = newId[ha], a1 = newId[nextHe(ha)];
          const uint32_t b0 = newId[hb], b1 = newId[nextHe(hb)];
          if (!((a0 == b0 && a1 == b1) || (a0 == b1 && a1 == b0))) continue;
          const uint32_t f = ha / 3;
          for (uint32_t k = 0; k < 3; ++k) {
            const uint32_t h = 3 * f + k, t = s.twin[h];
            if (t == kNone) continue;
            s.twin[h] = s.twin[t] = kNone;
            changed = true;
          }
        }
      }
    }
    if (!changed || round > 64) {
      st.nonManifoldVertices += nonManifoldVertices;
      break;
    }
  }
  st.verticesSplit += splitVertices;
  // 5. Output arrays (vertex v < nw keeps its welded id; split copies come after).
  const uint32_t nv = static_cast<uint32_t>(vertexOf.size());
  s.tris = std::move(tris);  // renumbered in place
  for (uint32_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) s.tris[f][k] = newId[3 * f + k];
  std::vector<uint32_t>().swap(newId);
  s.positions = std::move(w.positions);
  s.positions.resize(nv);
  for (uint32_t v = nv0; v < nv; ++v) s.positions[v] = s.positions[vertexOf[v]];
  s.positions.shrink_to_fit();
  if (!w.colours.empty()) {
    s.colours = std::move(w.colours);
    s.colours.resize(nv);
    for (uint32_t v = nv0; v < nv; ++v) s.colours[v] = s.colours[vertexOf[v]];
    s.colours.shrink_to_fit();
  }
  std::vector<uint32_t>().swap(vertexOf);
  // One outgoing half-edge per vertex, the open one where the fan is open.
  s.vHe.assign(nv, kNone);
  for (uint32_t h = 0; h < 3 * nf; ++h) {
    uint32_t& e = s.vHe[s.origin(h)];
    if (e == kNone || s.twin[h] == kNone) e = h;
  }
  for (uint32_t t : s.twin) st.boundaryEdges += t == kNone;
  return s;
}

Surface weldAndRepair(const std::vector<glm::vec3>& inPos, const std::vector<glm::u8vec4>& inCol,
                      const std::vector<std::array<uint32_t, 3>>& inTris, ChartingStats& st) {
  const char* fn = "buildPatchLayout";
  // 1. Weld referenced positions.
  Welder w(std::min(inPos.size(), inTris.size() * 3));
  {
    std::vector<uint32_t> remap(inPos.size(), kNone);
    w.tris.reserve(inTris.size());
    for (const auto& t : inTris) {
      std::array<uint32_t, 3> r;
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = t[k];
        if (v >= inPos.size())
          throw InputError(std::string(fn) + ": triangle index " + std::to_string(v) + " outside the " +
                           std::to_string(inPos.size()) + " positions");
        if (remap[v] == kNone) {
          const glm::vec3& p = inPos[v];
          if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
            throw InputError(std::string(fn) + ": vertex " + std::to_string(v) + " is not finite");
          remap[v] = w.add(p, inCol.empty() ? nullptr : &inCol[v]);
        }
        r[k] = remap[v];
      }
      w.tris.push_back(r);
    }
  }
  return repairWelded(std::move(w), st);
}

}  // namespace gimlod::charting
