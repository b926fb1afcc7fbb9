// The layout builder: corners, corner insertion, splits of patches with too many sides, and the
// layout's patches and sides.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5; Purnomo, Cohen, Kumar, SGP 2004 (patches).
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <unordered_map>
#include <utility>

#include <glm/geometric.hpp>

#include "atlas/mesh/charting_internal.h"
#include "atlas/mesh/patch_topology.h"

namespace gimlod::charting {
namespace {

class LayoutBuilder {
 public:
  // labels: a cluster per face (any ids), renumbered in place by first face.
  LayoutBuilder(const Surface& s, std::vector<uint32_t> labels, const ChartingOptions& o, ChartingStats& st)
      : s_(s), o_(o), st_(st), label_(std::move(labels)) {
    const uint32_t nf = static_cast<uint32_t>(s.tris.size());
    {
      uint32_t maxLabel = 0;
      for (uint32_t l : label_) maxLabel = std::max(maxLabel, l);
      std::vector<uint32_t> compact(size_t{maxLabel} + 1, kNone), count;
      for (uint32_t f = 0; f < nf; ++f) {
        uint32_t& c = compact[label_[f]];
        if (c == kNone) c = static_cast<uint32_t>(count.size()), count.push_back(0);
        label_[f] = c;
        ++count[c];
      }
      faces_.resize(count.size());
      for (size_t c = 0; c < count.size(); ++c) faces_[c].reserve(count[c]);
      for (uint32_t f = 0; f < nf; ++f) faces_[label_[f]].push_back(f);
    }
    const uint32_t nv = static_cast<uint32_t>(s.positions.size());
    corner_.assign(nv, 0);
    std::vector<uint8_t> open(nv, 0);
    for (uint32_t h = 0; h < 3 * nf; ++h)
      if (s.twin[h] == kNone) open[s.origin(h)] = open[s.dest(h)] = 1;
    for (uint32_t v = 0; v < nv; ++v) {
      uint32_t first = kNone, second = kNone;
      bool three = false;
      s.forFaces(v, [&](uint32_t f) {
        const uint32_t c = label_[f];
        if (first == kNone || c == first)
          first = c;
        else if (second == kNone || c == second)
          second = c;
        else
          three = true;
        return three;
      });
      corner_[v] = three || (open[v] && second != kNone);
    }
  }

  void fix() {
    // Corner insertion for patches with too few sides.
    for (uint32_t p = 0; p < faces_.size(); ++p) insertCorners(p);
    // Split patches with too many sides (halves have at least minSides and fewer sides).
    std::vector<uint32_t> work(faces_.size());
    std::iota(work.begin(), work.end(), 0u);
    size_t budget = 64 * faces_.size() + 10000;  // guards against ping-pong of new corners
    while (!work.empty() && budget-- > 0) {
      const uint32_t p = work.back();
      work.pop_back();
      const std::vector<uint32_t> loop = boundaryLoop(p);
      uint32_t corners = 0;
      for (uint32_t h : loop) corners += corner_[s_.origin(h)];
      if (corners <= o_.maxSides) continue;
      const uint32_t q = split(p, loop, work);
      if (q == kNone) continue;
      ++st_.patchesSplit;
      work.push_back(p);
      work.push_back(q);
    }
    // Patches still out of range (no cut found, or the budget ran out).
    unfixed_ = 0;
    for (uint32_t p = 0; p < faces_.size(); ++p) {
      uint32_t corners = 0;
      for (uint32_t h : boundaryLoop(p)) corners += corner_[s_.origin(h)];
      unfixed_ += corners > o_.maxSides || corners < o_.minSides;
    }
  }

  PatchLayout output() {
    // Patches only: the caller moves the surface's positions, colours and triangles in.
    PatchLayout out;
    const uint32_t np = static_cast<uint32_t>(faces_.size());
    out.patches.resize(np);
    std::unordered_map<uint32_t, uint32_t> sideOf;  // patch-boundary half-edge -> side index
    sideOf.reserve(size_t{np} * 64);
    std::vector<std::vector<uint32_t>> firstHe(np);
    for (uint32_t p = 0; p < np; ++p) {
      Patch& P = out.patches[p];
      const std::vector<uint32_t> loop = boundaryLoop(p);
      P.triangles = std::move(faces_[p]);  // faces_ is not used after output()
      std::sort(P.triangles.begin(), P.triangles.end());
      size_t start = 0;
      while (start < loop.size() && !corner_[s_.origin(loop[start])]) ++start;
      if (start == loop.size()) start = 0;  // no corner (only if insertion failed)
      for (size_t i = 0; i < loop.size(); ++i) {
        const uint32_t h = loop[(start + i) % loop.size()];
        if (i == 0 || corner_[s_.origin(h)]) {
          P.sides.emplace_back();
          P.sides.back().vertices.push_back(s_.origin(h));
          const uint32_t t = s_.twin[h];
          P.sides.back().neighbourPatch = t == kNone ? -1 : static_cast<int32_t>(label_[t / 3]);
          firstHe[p].push_back(h);
        }
        P.sides.back().vertices.push_back(s_.dest(h));
        sideOf[h] = static_cast<uint32_t>(P.sides.size() - 1);
      }
    }
    for (uint32_t p = 0; p < np; ++p) {
      for (size_t i = 0; i < out.patches[p].sides.size(); ++i) {
        PatchSide& side = out.patches[p].sides[i];
        if (side.neighbourPatch < 0) continue;
        side.neighbourSide = sideOf.at(s_.twin[firstHe[p][i]]);
        side.reversed = true;
      }
    }
    return out;
  }

  uint32_t unfixed() const { return unfixed_; }
  const std::vector<uint32_t>& labels() const { return label_; }
  size_t bytes() const {
    return label_.size() * 8 + corner_.size() + local_.size() * 4 + ldist_.capacity() * 8 +
           (lprev_.capacity() + lvisit_.capacity() + lpos_.capacity()) * 4;
  }

 private:
  uint32_t nextBoundary(uint32_t h, uint32_t c) const { return nextBoundaryHe(s_.twin, label_, h, c); }

  std::vector<uint32_t> boundaryLoop(uint32_t p) const {
    std::vector<uint32_t> loop;
    uint32_t start = kNone;
    for (uint32_t f : faces_[p]) {
      for (uint32_t k = 0; k < 3 && start == kNone; ++k) {
        const uint32_t h = 3 * f + k, t = s_.twin[h];
        if (t == kNone || label_[t / 3] != p) start = h;
      }
      if (start != kNone) break;
    }
    if (start == kNone) return loop;
    uint32_t h = start;
    do {
      loop.push_back(h);
      h = nextBoundary(h, p);
    } while (h != start && loop.size() <= 3 * faces_[p].size());
    return loop;
  }

  double length(uint32_t h) const {
    return glm::length(glm::dvec3(s_.positions[s_.origin(h)]) - glm::dvec3(s_.positions[s_.dest(h)]));
  }

  // Adds corners at the middle (by length) of the longest runs until the patch has minSides.
  void insertCorners(uint32_t p) {
    const std::vector<uint32_t> loop = boundaryLoop(p);
    const size_t L = loop.size();
    std::vector<double> cum(L + 1, 0);
    for (size_t i = 0; i < L; ++i) cum[i + 1] = cum[i] + length(loop[i]);
    auto isCorner = [&](size_t i) { return corner_[s_.origin(loop[i % L])] != 0; };
    uint32_t corners = 0;
    for (size_t i = 0; i < L; ++i) corners += isCorner(i);
    if (corners >= o_.minSides) return;
    if (corners == 0) {
      // Spread minSides corners evenly by length.
      const double total = cum[L];
      size_t j = 0;
      for (uint32_t k = 0; k < o_.minSides && j < L; ++k) {
        const double target = total * k / o_.minSides;
        while (j + 1 < L && cum[j] < target) ++j;
        if (!isCorner(j)) {
          corner_[s_.origin(loop[j])] = 1;
          ++st_.cornersInserted;
        }
        ++j;
      }
      corners = 0;
      for (size_t i = 0; i < L; ++i) corners += isCorner(i);
    }
    while (corners < o_.minSides) {
      // Longest run (in edges >= 2) between consecutive corners.
      size_t first = 0;
      while (!isCorner(first)) ++first;
      size_t bestA = kNone, bestB = 0;
      double bestLen = -1;
      size_t a = first;
      for (size_t step = 0; step < corners; ++step) {
        size_t b = a + 1;
        while (!isCorner(b)) ++b;
        const double len = b <= L ? cum[b] - cum[a] : cum[L] - cum[a] + cum[b - L];
        if (b - a >= 2 && len > bestLen) bestLen = len, bestA = a, bestB = b;
        a = b;
      }
      if (bestA == kNone) return;  // cannot happen on a loop of >= 3 edges
      auto at = [&](size_t i) { return i <= L ? cum[i] : cum[L] + cum[i - L]; };
      const double mid = 0.5 * (at(bestA) + at(bestB));
      size_t pick = bestA + 1;
      double bestD = std::abs(at(pick) - mid);
      for (size_t i = bestA + 2; i < bestB; ++i)
        if (std::abs(at(i) - mid) < bestD) bestD = std::abs(at(i) - mid), pick = i;
      corner_[s_.origin(loop[pick % L])] = 1;
      ++st_.cornersInserted;
      ++corners;
    }
  }

  // Local numbering of patch p's vertices for split()'s work arrays (sized to the patch, not
  // the mesh); undone by clearLocal().
  void numberLocal(uint32_t p) {
    if (local_.empty()) local_.assign(s_.positions.size(), kNone);
    lverts_.clear();
    for (uint32_t f : faces_[p])
      for (uint32_t v : s_.tris[f])
        if (local_[v] == kNone) local_[v] = static_cast<uint32_t>(lverts_.size()), lverts_.push_back(v);
    const size_t n = lverts_.size();
    ldist_.assign(n, 0);
    lprev_.assign(n, kNone);
    lvisit_.assign(n, 0);
    lpos_.assign(n, kNone);  // position on the boundary loop; kNone: not on it
    lrun_ = 0;
  }
  void clearLocal() {
    for (uint32_t v : lverts_) local_[v] = kNone;
    lverts_.clear();
  }

  // shortestFrom's graph for shortestInteriorPaths: patch p's interior edges (a's excepted, so
  // no path returns to it), with lengths in double, and the paths in the l* work arrays.
  struct InteriorSearch {
    LayoutBuilder& b;
    uint32_t p, a, run;
    void start(uint32_t source) {
      const uint32_t l = b.local_[source];
      b.ldist_[l] = 0;
      b.lprev_[l] = kNone;
      b.lvisit_[l] = run;
    }
    double distance(uint32_t v) const { return b.ldist_[b.local_[v]]; }
    bool relax(uint32_t w, double d, uint32_t u) {
      const uint32_t lw = b.local_[w];
      if (b.lvisit_[lw] == run && !(d < b.ldist_[lw])) return false;
      b.lvisit_[lw] = run;
      b.ldist_[lw] = d;
      b.lprev_[lw] = u;
      return true;
    }
    template <class Fn>
    void forNeighbours(uint32_t u, Fn&& fn) {
      b.s_.facesAround(u, b.around_);
      for (const uint32_t f : b.around_) {
        if (b.label_[f] != p) continue;
        for (uint32_t k = 0; k < 3; ++k) {
          const uint32_t h = 3 * f + k;
          uint32_t w;
          if (b.s_.origin(h) == u)
            w = b.s_.dest(h);
          else if (b.s_.dest(h) == u)
            w = b.s_.origin(h);
          else
            continue;
          const uint32_t t = b.s_.twin[h];
          if (t == kNone || b.label_[t / 3] != p || w == a) continue;  // boundary edge
          fn(w, b.length(h));
        }
      }
    }
  };

  // Shortest paths from boundary vertex a through the interior of patch p (interior vertices
  // and interior edges only) to every boundary vertex it reaches; returns those vertices.
  // ldist_ / lprev_ hold the paths for this run (lvisit_ == the returned run id).
  std::vector<uint32_t> shortestFrom(uint32_t p, uint32_t a, uint32_t& run) {
    run = ++lrun_;
    std::vector<uint32_t> reached;
    InteriorSearch search{*this, p, a, run};
    shortestInteriorPaths(search, a, [&](uint32_t u) {
      if (u != a && lpos_[local_[u]] != kNone) {  // boundary vertices end paths
        reached.push_back(u);
        return PathStep::kEnd;
      }
      return PathStep::kThrough;
    });
    return reached;
  }

  // Splits patch p along a shortest interior path between two boundary vertices so that both
  // halves have minSides..maxSides sides (or at least fewer than p). Tries, in order: corner to
  // corner; corner to any boundary vertex; any boundary vertex to any. A non-corner endpoint
  // becomes a corner (the neighbour across gains a side; its patches are queued in `touched`).
  // Returns the new patch (p keeps the other half), or kNone if no cut was found.
  uint32_t split(uint32_t p, const std::vector<uint32_t>& loop, std::vector<uint32_t>& touched) {
    numberLocal(p);
    const uint32_t q = splitNumbered(p, loop, touched);
    clearLocal();
    return q;
  }

  uint32_t splitNumbered(uint32_t p, const std::vector<uint32_t>& loop, std::vector<uint32_t>& touched) {
    const size_t L = loop.size();
    std::vector<uint32_t> cc(2 * L + 1, 0);  // corners among loop positions [0, t)
    for (size_t t = 0; t < L; ++t) lpos_[local_[s_.origin(loop[t])]] = static_cast<uint32_t>(t);
    for (size_t t = 0; t < 2 * L; ++t) cc[t + 1] = cc[t] + corner_[s_.origin(loop[t % L])];
    const uint32_t k = cc[L];
    std::vector<uint32_t> cornerPos, allPos;
    for (size_t t = 0; t < L; ++t) {
      if (corner_[s_.origin(loop[t])]) cornerPos.push_back(static_cast<uint32_t>(t));
    }
    const size_t stride = std::max<size_t>(1, L / 64);
    for (size_t t = 0; t < L; t += stride) allPos.push_back(static_cast<uint32_t>(t));
    for (int level = 0; level < 3; ++level) {
      const std::vector<uint32_t>& starts = level < 2 ? cornerPos : allPos;
      double bestScore = std::numeric_limits<double>::infinity();
      std::vector<uint32_t> best;
      for (uint32_t i : starts) {
        const uint32_t a = s_.origin(loop[i]);
        uint32_t run = 0;
        const std::vector<uint32_t> reached = shortestFrom(p, a, run);
        for (uint32_t b : reached) {
          const uint32_t j = lpos_[local_[b]];
          if (level == 0 && !corner_[b]) continue;
          // Sides of the two halves: corners on each closed loop segment, endpoints included.
          const uint32_t i2 = i, j2 = j < i ? j + static_cast<uint32_t>(L) : j;
          const uint32_t inner1 = cc[j2] - cc[i2 + 1];
          const uint32_t inner2 = k - inner1 - corner_[a] - corner_[b];
          const uint32_t s1 = inner1 + 2, s2 = inner2 + 2;
          if (s1 < o_.minSides || s2 < o_.minSides) continue;
          const uint32_t worst = std::max(s1, s2);
          if (worst >= std::max<uint32_t>(k, o_.maxSides + 1) && worst > o_.maxSides) continue;
          const double over = worst > o_.maxSides ? double(worst - o_.maxSides) : 0.0;
          const double score =
              ldist_[local_[b]] * (1.0 + 0.25 * std::abs(double(s1) - double(s2))) * (1.0 + 10.0 * over);
          if (score < bestScore) {
            bestScore = score;
            best.clear();
            for (uint32_t v = b; v != kNone; v = lprev_[local_[v]]) best.push_back(v);
          }
        }
      }
      if (best.size() < 2) continue;
      std::reverse(best.begin(), best.end());
      const uint32_t q = applyCut(p, best);
      if (q == kNone) continue;
      for (uint32_t v : {best.front(), best.back()}) {
        if (corner_[v]) continue;
        corner_[v] = 1;
        ++st_.cornersInserted;
        s_.facesAround(v, around_);
        for (uint32_t f : around_) touched.push_back(label_[f]);
      }
      return q;
    }
    return kNone;
  }

  uint32_t applyCut(uint32_t p, const std::vector<uint32_t>& path) {
    std::vector<uint32_t> marked;  // the path's half-edges, both directions
    uint32_t seedFace = kNone, otherFace = kNone;
    for (size_t i = 0; i + 1 < path.size(); ++i) {
      const uint32_t x = path[i], y = path[i + 1];
      s_.facesAround(x, around_);
      for (const uint32_t f : around_) {
        if (label_[f] != p) continue;
        for (uint32_t k = 0; k < 3; ++k) {
          const uint32_t h = 3 * f + k;
          if (s_.origin(h) == x && s_.dest(h) == y) {
            marked.push_back(h);
            if (seedFace == kNone) seedFace = f, otherFace = s_.twin[h] / 3;
          } else if (s_.origin(h) == y && s_.dest(h) == x) {
            marked.push_back(h);
          }
        }
      }
    }
    std::sort(marked.begin(), marked.end());
    uint32_t result = kNone;
    if (seedFace != kNone) {
      // Flood p's faces from the seed without crossing the cut; reached faces are relabelled
      // to the would-be new patch (so the label test also marks them visited).
      const auto mark = static_cast<uint32_t>(faces_.size());
      std::vector<uint32_t> stack{seedFace}, side;
      label_[seedFace] = mark;
      while (!stack.empty()) {
        const uint32_t f = stack.back();
        stack.pop_back();
        side.push_back(f);
        for (uint32_t k = 0; k < 3; ++k) {
          const uint32_t h = 3 * f + k, t = s_.twin[h];
          if (t == kNone || label_[t / 3] != p || std::binary_search(marked.begin(), marked.end(), h)) continue;
          label_[t / 3] = mark;
          stack.push_back(t / 3);
        }
      }
      if (label_[otherFace] != mark && side.size() < faces_[p].size()) {
        result = mark;
        faces_.emplace_back();
        faces_[result] = std::move(side);
        std::vector<uint32_t> rest;
        for (uint32_t f : faces_[p])
          if (label_[f] == p) rest.push_back(f);
        faces_[p] = std::move(rest);
      } else {
        for (uint32_t f : side) label_[f] = p;
      }
    }
    return result;
  }

  const Surface& s_;
  const ChartingOptions& o_;
  ChartingStats& st_;
  std::vector<uint32_t> label_;
  std::vector<std::vector<uint32_t>> faces_;
  std::vector<uint8_t> corner_;
  // split()'s work arrays: local_ maps a vertex to its index in the patch being split (kNone
  // elsewhere); the l* arrays are indexed by that.
  std::vector<uint32_t> local_, lverts_, lprev_, lvisit_, lpos_, around_;
  std::vector<double> ldist_;
  uint32_t lrun_ = 0, unfixed_ = 0;
};

// Fills the final statistics from the layout's patches.
void finishStats(const Surface& s, const PatchLayout& out, const Frame& fr, ChartingStats& st) {
  st.outputTriangles = s.tris.size();
  st.outputVertices = s.positions.size();
  st.charts = static_cast<uint32_t>(out.patches.size());
  st.sidesHistogram.assign(1, 0);
  auto npos = [&](uint32_t v) { return (glm::dvec3(s.positions[v]) - fr.centre) / fr.diag; };
  double sum = 0, area = 0;
  st.maxPlanarityError = 0;
  for (const Patch& p : out.patches) {
    const size_t n = p.sides.size();
    if (st.sidesHistogram.size() <= n) st.sidesHistogram.resize(n + 1, 0);
    ++st.sidesHistogram[n];
    Moments M;
    for (uint32_t f : p.triangles) M.add(triangleMoments(npos(s.tris[f][0]), npos(s.tris[f][1]), npos(s.tris[f][2])));
    const double rms = std::sqrt(planeMsd(M));
    st.maxPlanarityError = std::max(st.maxPlanarityError, rms);
    sum += rms * M.area;
    area += M.area;
  }
  st.meanPlanarityError = area > 0 ? sum / area : 0;
}

}  // namespace

// Consumes the surface: its positions, colours and triangles move into the layout.
PatchLayout layoutFromLabels(Surface& s, std::vector<uint32_t> labels, const Frame& fr, const ChartingOptions& o,
                             ChartingStats& st, size_t clusterBytes) {
  const auto t0 = Clock::now();
  PatchLayout out;
  {
    LayoutBuilder lb(s, std::move(labels), o, st);
    lb.fix();
    out = lb.output();
    st.peakBytesEstimate = std::max<uint64_t>(st.peakBytesEstimate, s.bytes() + std::max(clusterBytes, lb.bytes()));
    st.patchesUnfixed = lb.unfixed();
  }
  finishStats(s, out, fr, st);
  out.positions = std::move(s.positions);
  out.colours = std::move(s.colours);
  out.triangles = std::move(s.tris);
  st.sidesSeconds += since(t0);
  return out;
}

}  // namespace gimlod::charting
