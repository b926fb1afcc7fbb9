#include "atlas/terrain/void_fill.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace gimlod {
namespace {

constexpr int kRelaxSweeps = 4;
constexpr double kFilter[4] = {1.0, 3.0, 3.0, 1.0};

// The pyramid's global geometry: per level, the cell centres along each axis in level-0 sample
// coordinates (weighted like the pull).
class Geometry {
 public:
  Geometry(uint32_t width, uint32_t height) {
    px_.emplace_back(width);
    py_.emplace_back(height);
    for (uint32_t i = 0; i < width; ++i) px_[0][i] = i;
    for (uint32_t i = 0; i < height; ++i) py_[0][i] = i;
  }
  void ensure(uint32_t level) {
    while (px_.size() <= level) {
      px_.push_back(coarsen(px_.back()));
      py_.push_back(coarsen(py_.back()));
    }
  }
  int64_t width(uint32_t l) const { return int64_t(px_[l].size()); }
  int64_t height(uint32_t l) const { return int64_t(py_[l].size()); }
  const std::vector<double>& px(uint32_t l) const { return px_[l]; }
  const std::vector<double>& py(uint32_t l) const { return py_[l]; }
  CellWindow all(uint32_t l) const { return {0, 0, width(l), height(l)}; }
  CellWindow clamp(CellWindow w, uint32_t l) const {
    return {std::max<int64_t>(w.x0, 0), std::max<int64_t>(w.y0, 0), std::min(w.x1, width(l)),
            std::min(w.y1, height(l))};
  }

 private:
  static std::vector<double> coarsen(const std::vector<double>& fine) {
    const int64_t fn = int64_t(fine.size()), cn = (fn + 1) / 2;
    std::vector<double> c(static_cast<size_t>(cn), 0.0);
    for (int64_t i = 0; i < cn; ++i) {
      double sw = 0, sp = 0;
      for (int a = 0; a < 4; ++a) {
        const int64_t f = 2 * i - 1 + a;
        if (f >= 0 && f < fn) {
          sw += kFilter[a];
          sp += kFilter[a] * fine[size_t(f)];
        }
      }
      c[size_t(i)] = sp / sw;
    }
    return c;
  }
  std::vector<std::vector<double>> px_, py_;
};

// One level's cells over a window: values and whether each is valid (pulled, or filled).
struct Level {
  CellWindow w;
  std::vector<float> v;
  std::vector<uint8_t> ok;
  explicit Level(CellWindow win = {}) : w(win), v(win.cells(), 0.f), ok(win.cells(), 0) {}
  size_t at(int64_t x, int64_t y) const { return size_t(y - w.y0) * size_t(w.width()) + size_t(x - w.x0); }
  bool covers(const CellWindow& o) const {
    return o.empty() || (o.x0 >= w.x0 && o.y0 >= w.y0 && o.x1 <= w.x1 && o.y1 <= w.y1);
  }
};

CellWindow expand(const CellWindow& w, int64_t m) { return {w.x0 - m, w.y0 - m, w.x1 + m, w.y1 + m}; }
CellWindow unite(const CellWindow& a, const CellWindow& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  return {std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1), std::max(a.y1, b.y1)};
}
// The level-l cells the pull of a level-(l+1) window reads: 2i-1 .. 2i+2.
CellWindow childSupport(const CellWindow& w) { return {2 * w.x0 - 1, 2 * w.y0 - 1, 2 * w.x1 + 1, 2 * w.y1 + 1}; }
// The level-(l+1) cells the push of a level-l window reads: x/2 and its neighbours.
CellWindow parents(const CellWindow& w) { return {w.x0 / 2 - 1, w.y0 / 2 - 1, (w.x1 - 1) / 2 + 2, (w.y1 - 1) / 2 + 2}; }

// Pulls level l+1 over `target` (clamped) from `fine` (level l), which must cover its taps.
Level pull(const Geometry& g, uint32_t l, const Level& fine, CellWindow target, bool* anyVoid) {
  target = g.clamp(target, l + 1);
  if (!fine.covers(g.clamp(childSupport(target), l))) throw std::logic_error("pull: the fine window is too small");
  const int64_t fw = g.width(l), fh = g.height(l);
  Level c(target);
  for (int64_t j = target.y0; j < target.y1; ++j)
    for (int64_t i = target.x0; i < target.x1; ++i) {
      double sum = 0.0, weight = 0.0;
      for (int b = 0; b < 4; ++b) {
        const int64_t fy = 2 * j - 1 + b;
        if (fy < 0 || fy >= fh) continue;
        for (int a = 0; a < 4; ++a) {
          const int64_t fx = 2 * i - 1 + a;
          if (fx < 0 || fx >= fw) continue;
          const size_t k = fine.at(fx, fy);
          if (fine.ok[k]) {
            const double w = kFilter[b] * kFilter[a];
            sum += w * fine.v[k];
            weight += w;
          }
        }
      }
      const size_t k = c.at(i, j);
      if (weight > 0) {
        c.v[k] = static_cast<float>(sum / weight);
        c.ok[k] = 1;
      } else {
        *anyVoid = true;
      }
    }
  return c;
}

// The push's interpolation taps of a fine axis position: coarse centres c0 <= c1 around it, at
// fraction t.
struct Tap {
  int64_t c0, c1;
  double t;
};
Tap pushTap(const std::vector<double>& fine, const std::vector<double>& coarse, int64_t x) {
  const int64_t last = int64_t(coarse.size()) - 1;
  const int64_t i = std::min(x / 2, last);
  Tap t{i, i, 0.0};
  if (fine[size_t(x)] < coarse[size_t(i)] && i > 0)
    t.c0 = i - 1;
  else if (fine[size_t(x)] > coarse[size_t(i)] && i < last)
    t.c1 = i + 1;
  if (t.c0 != t.c1)
    t.t =
        std::clamp((fine[size_t(x)] - coarse[size_t(t.c0)]) / (coarse[size_t(t.c1)] - coarse[size_t(t.c0)]), 0.0, 1.0);
  return t;
}

// Fills the void cells of `f` (level l) inside `relax` by bilinear interpolation of `coarse`
// (level l+1, final; it must cover their taps), then relaxes them: Gauss-Seidel in raster order
// (whole levels only), or Jacobi (exact at cells kRelaxSweeps or more inside `relax`, or at the
// level's edge).
void push(const Geometry& g, uint32_t l, const Level& coarse, Level& f, CellWindow relax, bool gaussSeidel) {
  relax = g.clamp(relax, l);
  if (!f.covers(relax)) throw std::logic_error("push: the level's window is too small");
  std::vector<Tap> tx(size_t(relax.width())), ty(size_t(relax.height()));
  for (int64_t x = relax.x0; x < relax.x1; ++x) tx[size_t(x - relax.x0)] = pushTap(g.px(l), g.px(l + 1), x);
  for (int64_t y = relax.y0; y < relax.y1; ++y) ty[size_t(y - relax.y0)] = pushTap(g.py(l), g.py(l + 1), y);
  std::vector<size_t> filled;
  for (int64_t y = relax.y0; y < relax.y1; ++y) {
    const Tap& a = ty[size_t(y - relax.y0)];
    for (int64_t x = relax.x0; x < relax.x1; ++x) {
      const size_t k = f.at(x, y);
      if (f.ok[k]) continue;
      const Tap& b = tx[size_t(x - relax.x0)];
      const double top = (1 - b.t) * coarse.v[coarse.at(b.c0, a.c0)] + b.t * coarse.v[coarse.at(b.c1, a.c0)];
      const double bot = (1 - b.t) * coarse.v[coarse.at(b.c0, a.c1)] + b.t * coarse.v[coarse.at(b.c1, a.c1)];
      f.v[k] = static_cast<float>((1 - a.t) * top + a.t * bot);
      f.ok[k] = 1;
      filled.push_back(k);
    }
  }
  const int64_t lw = g.width(l), lh = g.height(l), ww = f.w.width();
  std::vector<float> old;
  for (int sweep = 0; sweep < kRelaxSweeps; ++sweep) {
    if (!gaussSeidel) old = f.v;
    const std::vector<float>& src = gaussSeidel ? f.v : old;
    for (size_t k : filled) {
      const int64_t x = f.w.x0 + int64_t(k % size_t(ww)), y = f.w.y0 + int64_t(k / size_t(ww));
      double sum = 0.0;
      int count = 0;
      // Neighbours inside the level; in a window, those outside it (or not yet filled) are
      // skipped, which is inexact only within kRelaxSweeps of the window's edge.
      auto add = [&](int64_t nx, int64_t ny, size_t nk) {
        if (nx < 0 || ny < 0 || nx >= lw || ny >= lh) return;
        if (nx < f.w.x0 || ny < f.w.y0 || nx >= f.w.x1 || ny >= f.w.y1 || !f.ok[nk]) return;
        sum += src[nk];
        ++count;
      };
      if (x > 0) add(x - 1, y, k - 1);
      if (x + 1 < lw) add(x + 1, y, k + 1);
      if (y > 0) add(x, y - 1, k - size_t(ww));
      if (y + 1 < lh) add(x, y + 1, k + size_t(ww));
      if (count > 0) f.v[k] = static_cast<float>(sum / count);
    }
  }
}

// The windows a core's fill needs, level by level up to `top`: relax[l] (pushed and relaxed) and
// pullWin[l] (pulled from level 0). topPulled: the top level's values are pulled here (it has no
// voids); otherwise they come whole from memory.
struct FillPlan {
  std::vector<CellWindow> relax, pullWin;
};
FillPlan planFill(const Geometry& g, const CellWindow& core, uint32_t top, bool topPulled) {
  FillPlan p;
  p.relax.resize(top);
  p.pullWin.resize(top + 1);
  CellWindow need = core;
  for (uint32_t l = 0; l < top; ++l) {
    p.relax[l] = g.clamp(expand(need, kRelaxSweeps), l);
    need = g.clamp(parents(p.relax[l]), l + 1);
  }
  p.pullWin[top] = topPulled ? need : CellWindow{};
  for (uint32_t l = top; l-- > 0;) {
    CellWindow w = p.relax[l];
    if (!p.pullWin[l + 1].empty()) w = unite(w, childSupport(p.pullWin[l + 1]));
    p.pullWin[l] = g.clamp(w, l);
  }
  return p;
}

// Pulls levels 1..top of a plan from its level-0 window, then pushes down from `topLevel` (level
// top, whole from memory when given, else pulled); returns level 0.
Level fillWindow(const Geometry& g, const FillPlan& p, Level level0, uint32_t top, const Level* topLevel) {
  std::vector<Level> levels;
  levels.push_back(std::move(level0));
  bool anyVoid = false;
  for (uint32_t l = 1; l <= top; ++l) {
    if (p.pullWin[l].empty()) break;
    levels.push_back(pull(g, l - 1, levels.back(), p.pullWin[l], &anyVoid));
  }
  for (uint32_t l = top; l-- > 0;) {
    const Level& coarse = l + 1 == top && topLevel ? *topLevel : levels[l + 1];
    push(g, l, coarse, levels[l], p.relax[l], false);
  }
  return std::move(levels[0]);
}

}  // namespace

uint64_t fillVoids(std::vector<float>& heights, const std::vector<bool>& voidMask, uint32_t width, uint32_t height) {
  const size_t n = size_t{width} * height;
  if (heights.size() != n || voidMask.size() != n)
    throw std::invalid_argument("fillVoids: heights/mask size does not match width x height");
  uint64_t voids = 0;
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (size_t i = 0; i < n; ++i) {
    if (voidMask[i]) {
      ++voids;
    } else {
      lo = std::min(lo, heights[i]);
      hi = std::max(hi, heights[i]);
    }
  }
  if (voids == 0) return 0;
  if (voids == n) throw std::invalid_argument("fillVoids: no valid sample");

  Geometry g(width, height);
  std::vector<Level> levels(1, Level(g.all(0)));
  for (size_t i = 0; i < n; ++i) {
    levels[0].v[i] = heights[i];
    levels[0].ok[i] = voidMask[i] ? 0 : 1;
  }
  // Pull to the first level without voids.
  for (bool anyVoid = true; anyVoid;) {
    anyVoid = false;
    const uint32_t l = uint32_t(levels.size() - 1);
    g.ensure(l + 1);
    levels.push_back(pull(g, l, levels.back(), g.all(l + 1), &anyVoid));
  }
  // Push: Gauss-Seidel down to kWindowedFillLevels, Jacobi below (as the windowed fill does).
  const uint32_t top = uint32_t(levels.size() - 1);
  for (uint32_t l = top; l-- > 0;) push(g, l, levels[l + 1], levels[l], g.all(l), l >= kWindowedFillLevels);
  for (size_t i = 0; i < n; ++i)
    if (voidMask[i]) heights[i] = std::clamp(levels[0].v[i], lo, hi);
  return voids;
}

void fillVoidsWindowed(uint32_t width, uint32_t height, float lo, float hi, const WindowedFill& io,
                       uint64_t windowSamples) {
  Geometry g(width, height);
  const uint32_t c = kWindowedFillLevels;
  g.ensure(c);
  // The margin a window needs around its core, in level-0 samples (generous).
  const int64_t margin = int64_t(kRelaxSweeps + 4) << (c + 1);
  auto readLevel0 = [&](const CellWindow& w) {
    Level l(w);
    io.read(w, l.v.data(), l.ok.data());
    return l;
  };

  // 1. Level c, whole, band by band of its rows; and which levels up to c have voids.
  Level coarse(g.all(c));
  std::vector<bool> levelHasVoids(c + 1, false);
  levelHasVoids[0] = true;
  {
    const int64_t rowsPerBand =
        std::max<int64_t>(1, (int64_t(windowSamples) / std::max<int64_t>(width, 1) - 2 * margin) >> c);
    for (int64_t j0 = 0; j0 < g.height(c); j0 += rowsPerBand) {
      const CellWindow need{0, j0, g.width(c), std::min(j0 + rowsPerBand, g.height(c))};
      std::vector<CellWindow> win(c + 1);
      win[c] = need;
      for (uint32_t l = c; l-- > 0;) win[l] = g.clamp(childSupport(win[l + 1]), l);
      Level level = readLevel0(win[0]);
      for (uint32_t l = 1; l <= c; ++l) {
        bool anyVoid = false;
        level = pull(g, l - 1, level, win[l], &anyVoid);
        if (anyVoid) levelHasVoids[l] = true;
      }
      for (int64_t j = need.y0; j < need.y1; ++j)
        for (int64_t i = 0; i < need.x1; ++i) {
          coarse.v[coarse.at(i, j)] = level.v[level.at(i, j)];
          coarse.ok[coarse.at(i, j)] = level.ok[level.at(i, j)];
        }
    }
  }
  if (!levelHasVoids[1] && std::none_of(coarse.ok.begin(), coarse.ok.end(), [](uint8_t o) { return o != 0; }))
    throw std::invalid_argument("fillVoids: no valid sample");
  // The top of the push: the first level without voids if it is at most c (pulled locally by every
  // window), else level c, filled whole in memory from the levels above it.
  uint32_t top = c;
  bool topPulled = false;
  for (uint32_t l = 1; l <= c; ++l)
    if (!levelHasVoids[l]) {
      top = l;
      topPulled = true;
      break;
    }
  if (!topPulled) {
    if (std::none_of(coarse.ok.begin(), coarse.ok.end(), [](uint8_t o) { return o != 0; }))
      throw std::invalid_argument("fillVoids: no valid sample");
    std::vector<Level> levels;
    levels.push_back(std::move(coarse));
    for (bool anyVoid = true; anyVoid;) {
      anyVoid = false;
      const uint32_t l = c + uint32_t(levels.size() - 1);
      g.ensure(l + 1);
      levels.push_back(pull(g, l, levels.back(), g.all(l + 1), &anyVoid));
    }
    for (size_t i = levels.size() - 1; i-- > 0;)
      push(g, c + uint32_t(i), levels[i + 1], levels[i], g.all(c + uint32_t(i)), true);
    coarse = std::move(levels[0]);
  }

  // 2. Cores of level 0 with voids, each from a window around it.
  const int64_t side = std::max<int64_t>(256, int64_t(std::sqrt(double(windowSamples))) - 2 * margin);
  for (int64_t y0 = 0; y0 < height; y0 += side)
    for (int64_t x0 = 0; x0 < width; x0 += side) {
      const CellWindow core{x0, y0, std::min<int64_t>(x0 + side, width), std::min<int64_t>(y0 + side, height)};
      if (io.hasVoids && !io.hasVoids(core)) continue;
      const FillPlan plan = planFill(g, core, top, topPulled);
      Level filled = fillWindow(g, plan, readLevel0(plan.pullWin[0]), top, topPulled ? nullptr : &coarse);
      std::vector<float> out(core.cells());
      for (int64_t y = core.y0; y < core.y1; ++y)
        for (int64_t x = core.x0; x < core.x1; ++x) {
          const size_t k = filled.at(x, y);
          float v = filled.v[k];
          if (!filled.ok[k]) throw std::logic_error("fillVoidsWindowed: a core sample was left void");
          out[size_t(y - core.y0) * size_t(core.width()) + size_t(x - core.x0)] = v;
        }
      // Valid samples come back unchanged; fills are clamped to the valid range, as fillVoids does.
      Level original = readLevel0(core);
      for (size_t i = 0; i < out.size(); ++i) out[i] = original.ok[i] ? original.v[i] : std::clamp(out[i], lo, hi);
      io.write(core, out.data());
    }
}

}  // namespace gimlod
