// Validation of a chart layout, independent of how it was built.
#include "atlas/mesh/patch_layout.h"

#include <algorithm>
#include <string>
#include <unordered_map>

#include <glm/geometric.hpp>
#include <tbb/parallel_for.h>

namespace gimlod {

double sideLength(const PatchLayout& layout, const PatchSide& side) {
  double l = 0.0;
  for (size_t k = 0; k + 1 < side.vertices.size(); ++k) {
    l += glm::length(layout.positions[side.vertices[k + 1]] - layout.positions[side.vertices[k]]);
  }
  return l;
}

double meanSideLength(const PatchLayout& layout, uint32_t patch) {
  const Patch& p = layout.patches[patch];
  double sum = 0.0;
  for (const PatchSide& s : p.sides) sum += sideLength(layout, s);
  return sum / double(p.sides.size());
}

namespace {

// The undirected edge (a, b) as one key.
uint64_t undirectedKey(uint32_t a, uint32_t b) { return uint64_t{std::min(a, b)} << 32 | std::max(a, b); }

// The checks of patch pi of validatePatchLayout: a disk (Euler characteristic 1, one boundary
// loop), minSides..maxSides sides chaining along the loop and covering it, neighbours that point
// back with reversed vertices, open sides only on edges one triangle uses (edgeUse).
std::vector<std::string> checkPatch(const PatchLayout& L, size_t pi, uint32_t minSides, uint32_t maxSides,
                                    const std::unordered_map<uint64_t, uint32_t>& edgeUse) {
  const size_t nt = L.triangles.size();
  std::vector<std::string> pe;
  auto fail = [&](const std::string& m) {
    if (pe.size() < 100) pe.push_back(m);
  };
  const Patch& P = L.patches[pi];
  const std::string name = "patch " + std::to_string(pi);
  if (P.triangles.empty()) {
    fail(name + ": no triangles");
    return pe;
  }
  // Directed edges inside the patch, sorted; boundary = directed edges whose reverse is absent.
  // Sorted arrays, not hash maps: a patch of a 100M-triangle mesh has millions of edges.
  std::vector<uint64_t> directed;
  std::vector<uint32_t> verts;
  directed.reserve(3 * P.triangles.size());
  verts.reserve(3 * P.triangles.size());
  for (uint32_t f : P.triangles) {
    if (f >= nt) continue;
    const auto& t = L.triangles[f];
    for (int k = 0; k < 3; ++k) {
      directed.push_back(uint64_t{t[k]} << 32 | t[(k + 1) % 3]);
      verts.push_back(t[k]);
    }
  }
  std::sort(directed.begin(), directed.end());
  std::sort(verts.begin(), verts.end());
  const size_t vertexCount = size_t(std::unique(verts.begin(), verts.end()) - verts.begin());
  std::vector<uint32_t>().swap(verts);
  std::vector<std::pair<uint32_t, uint32_t>> nextB;  // boundary: origin -> dest, sorted by origin
  size_t undirected2 = 0, bcount = 0;
  bool bad = false;
  for (size_t i = 0; i < directed.size(); ++i) {
    const uint64_t k = directed[i];
    if (i > 0 && directed[i - 1] == k) {
      bad = true;
      continue;
    }
    const uint32_t a = static_cast<uint32_t>(k >> 32), b = static_cast<uint32_t>(k);
    const bool hasRev = std::binary_search(directed.begin(), directed.end(), uint64_t{b} << 32 | a);
    undirected2 += hasRev ? 1 : 2;
    if (!hasRev) {
      ++bcount;
      nextB.emplace_back(a, b);
    }
  }
  // (directed is sorted by origin, so nextB is too; an origin twice is a vertex on the loop twice.)
  for (size_t i = 1; i < nextB.size(); ++i) bad = bad || nextB[i - 1].first == nextB[i].first;
  if (bad) fail(name + ": repeated directed edge or boundary vertex visited twice");
  std::vector<uint64_t>().swap(directed);
  const int64_t chi = int64_t(vertexCount) - int64_t(undirected2 / 2) + int64_t(P.triangles.size());
  if (chi != 1) fail(name + ": Euler characteristic " + std::to_string(chi) + ", not 1");
  // The boundary edge from vertex a, nextB.end() if none.
  auto boundaryFrom = [&](uint32_t a) {
    const auto it = std::lower_bound(nextB.begin(), nextB.end(), std::pair<uint32_t, uint32_t>{a, 0u});
    return it != nextB.end() && it->first == a ? it : nextB.end();
  };
  // One loop.
  if (nextB.empty()) {
    fail(name + ": no boundary");
    return pe;
  }
  {
    uint32_t v = nextB.begin()->first;
    size_t len = 0;
    do {
      auto it = boundaryFrom(v);
      if (it == nextB.end()) break;
      v = it->second;
      ++len;
    } while (v != nextB.begin()->first && len <= bcount);
    if (len != bcount) fail(name + ": boundary is not a single loop");
  }
  if (P.sides.size() < minSides || P.sides.size() > maxSides)
    fail(name + ": " + std::to_string(P.sides.size()) + " sides");
  // Sides chain along the loop.
  size_t covered = 0;
  for (size_t si = 0; si < P.sides.size(); ++si) {
    const PatchSide& S = P.sides[si];
    const std::string sn = name + " side " + std::to_string(si);
    if (S.vertices.size() < 2) {
      fail(sn + ": fewer than 2 vertices");
      continue;
    }
    const PatchSide& N = P.sides[(si + 1) % P.sides.size()];
    if (!N.vertices.empty() && N.vertices.front() != S.vertices.back())
      fail(sn + ": does not end where the next side starts");
    for (size_t i = 0; i + 1 < S.vertices.size(); ++i) {
      auto it = boundaryFrom(S.vertices[i]);
      if (it == nextB.end() || it->second != S.vertices[i + 1]) {
        fail(sn + ": edge " + std::to_string(i) + " is not a boundary edge in loop order");
        break;
      }
      ++covered;
      if (S.neighbourPatch < 0 && edgeUse.at(undirectedKey(S.vertices[i], S.vertices[i + 1])) != 1)
        fail(sn + ": open side on an interior edge");
    }
    if (S.neighbourPatch >= 0) {
      if (size_t(S.neighbourPatch) >= L.patches.size() || S.neighbourSide >= L.patches[S.neighbourPatch].sides.size()) {
        fail(sn + ": neighbour out of range");
        continue;
      }
      const PatchSide& O = L.patches[S.neighbourPatch].sides[S.neighbourSide];
      if (O.neighbourPatch != int32_t(pi) || O.neighbourSide != si) fail(sn + ": neighbour side does not point back");
      std::vector<uint32_t> rev(S.vertices.rbegin(), S.vertices.rend());
      if (O.vertices != rev || !S.reversed) fail(sn + ": neighbour vertices not reversed");
    }
  }
  if (covered != bcount) fail(name + ": sides do not cover the boundary loop exactly");
  return pe;
}

}  // namespace

std::vector<std::string> validatePatchLayout(const PatchLayout& L, uint32_t minSides, uint32_t maxSides) {
  std::vector<std::string> errs;
  auto addErr = [&](const std::string& m) {
    if (errs.size() < 100) errs.push_back(m);
  };
  const size_t nv = L.positions.size(), nt = L.triangles.size();
  if (!L.colours.empty() && L.colours.size() != nv) addErr("colours: not one per position");
  for (size_t f = 0; f < nt; ++f)
    for (uint32_t v : L.triangles[f])
      if (v >= nv) {
        addErr("triangle " + std::to_string(f) + ": vertex out of range");
        return errs;
      }
  // Global use counts (undirected) of the edges of open sides only: the one global check.
  std::unordered_map<uint64_t, uint32_t> edgeUse;
  for (const Patch& P : L.patches)
    for (const PatchSide& S : P.sides)
      if (S.neighbourPatch < 0)
        for (size_t i = 0; i + 1 < S.vertices.size(); ++i) edgeUse[undirectedKey(S.vertices[i], S.vertices[i + 1])] = 0;
  if (!edgeUse.empty())
    for (const auto& t : L.triangles)
      for (int k = 0; k < 3; ++k) {
        const auto it = edgeUse.find(undirectedKey(t[k], t[(k + 1) % 3]));
        if (it != edgeUse.end()) ++it->second;
      }
  std::vector<int32_t> owner(nt, -1);
  for (size_t p = 0; p < L.patches.size(); ++p) {
    for (uint32_t f : L.patches[p].triangles) {
      if (f >= nt) {
        addErr("patch " + std::to_string(p) + ": triangle index out of range");
        continue;
      }
      if (owner[f] >= 0)
        addErr("triangle " + std::to_string(f) + ": in patches " + std::to_string(owner[f]) + " and " +
               std::to_string(p));
      owner[f] = static_cast<int32_t>(p);
    }
  }
  for (size_t f = 0; f < nt; ++f)
    if (owner[f] < 0) addErr("triangle " + std::to_string(f) + ": in no patch");
  std::vector<int32_t>().swap(owner);
  // Patches are checked in parallel, each into its own list; the lists are joined in order.
  std::vector<std::vector<std::string>> patchErrs(L.patches.size());
  tbb::parallel_for(size_t{0}, L.patches.size(),
                    [&](size_t pi) { patchErrs[pi] = checkPatch(L, pi, minSides, maxSides, edgeUse); });
  for (const auto& pe : patchErrs)
    for (const std::string& m : pe) addErr(m);
  return errs;
}

}  // namespace gimlod
