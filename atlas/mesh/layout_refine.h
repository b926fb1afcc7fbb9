// Refining a chart layout before and while it is resampled, so that its geometry images do not
// fold: shared sides straightened, side ears moved, and patches whose charts fold cut apart. A
// patch whose shape is far from a round blob (a narrow neck, a winding strip) is squeezed by any
// map onto a convex polygon, and where the squeeze is strong a texel of its quad charts spans
// surface that turns by more than a right angle, so the texel faces backwards (a flipped texel).
// Such a patch is cut in two along the shortest interior path across its neck or through the
// fold; the cut's ends become corners, so a neighbour there gains a side (within 8). A cut is
// kept only if it lowers the flipped-texel count (repairCharts). Patches too large for their
// charts' samples (the sampling error over a bound) are cut the same way, which is how a layout
// of few large patches gets exactly the charts its surface needs.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5 (patches split until they parameterize
// well); Sander, Snyder, Gortler, Hoppe, SIGGRAPH 2001 (charts split where stretch is high).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "atlas/mesh/patch_layout.h"
#include "atlas/mesh/resample.h"

namespace gimlod {

// Straightens the side `side` of patch `patch` shared with another patch: its vertex run becomes
// the shortest path between its two corners through the union of both patches (interior edges,
// no vertex of any other side of either), and the triangles between the old and the new run
// change patch. Jagged cluster borders (a side that wanders in and out of its neighbour) are
// what a fixed polygon border squeezes hardest; a straight side gives both patches a rounder
// shape. Returns false, unchanged, if the side is open or self-adjacent, no shorter path exists,
// or a part would not be a disk bordered by its other sides. With keepHalves, also when either
// patch would keep less than half its triangles: a side straightened across a patch's bulge can
// leave a sliver of a few dozen triangles, which the sides quad layout makes a single chart (on
// the armadillo, two 4-sided patches of 59 and 65 triangles, one with 154 flipped texels).
bool straightenSide(PatchLayout& layout, uint32_t patch, uint32_t side, bool keepHalves = false);

// Lengthens shared side `side` of patch `patch` by about `by` (in the input's units): its last
// corner (where patch A's next side starts, shared with a third patch C, which also borders the
// neighbour B there: three patches meet) moves along A's next side to the inner vertex nearest
// `by` of its arc length, at most half of it. C gives B the triangles between the two runs from
// the old corner and the shortest path through C's interior from the new corner to C's side with
// B. Every side count and link stays; A keeps its triangles. Returns false, unchanged, when the
// corner is not such a three-patch corner, the next side has no inner vertex, no path exists, or
// C's rest or B with its gain would not be a disk.
bool lengthenSide(PatchLayout& layout, uint32_t patch, uint32_t side, double by);

// A shared side much shorter than the other sides of its patches (three patches meeting twice a
// few edges apart, as clusters often do) is a whole chart edge in both quad layouts: its charts
// are squeezed towards triangles there, and their texels fold. Lengthens, with lengthenSide,
// every shared side shorter than `fraction` of the mean side of either of its patches to twice
// that, from whichever end lies on the longer next side. Returns the sides lengthened.
uint32_t lengthenShortSides(PatchLayout& layout, double fraction = 0.125);

// straightenSide on every shared side once per round, until a round changes nothing; returns the
// sides changed.
uint32_t straightenSides(PatchLayout& layout, uint32_t rounds = 2, bool keepHalves = false);

// Moves every "ear" of the given patches (all patches if empty) to the neighbour across its side:
// a triangle whose three vertices are consecutive vertices of one shared side. Its three
// vertices lie on one straight edge of the patch's polygon, so the parameterization gives it no
// area, and the side's samples (by arc length along its two edges) run off the map's interior
// samples (which cut across its third edge): texels there fold. Moved, the triangle is the
// neighbour's, whose side (and this one's) then takes the third edge; both patches stay disks.
// On an open side the ear's middle vertex becomes a corner instead; a patch that has 8 sides
// already is first cut at its neck (splitPatchAtNeck) if splitFull, which may change patches
// beyond its neighbours. Returns the ears mended.
uint32_t moveSideEars(PatchLayout& layout, const std::vector<uint32_t>& patches = {}, bool splitFull = true);

// What splitOpenSideEars changed: undo() puts the triangles and vertices back, for when the
// patches it split are dropped (a quad layout tried, then another straightened from the charted
// patches).
struct EarSplits {
  size_t positions = 0, colours = 0, triangles = 0;                   // the sizes before the splits
  std::vector<std::pair<uint32_t, std::array<uint32_t, 3>>> changed;  // triangles split in place, as they were
  void undo(PatchLayout& layout);
};

// Splits every ear left on an open side (one moveSideEars could not make a corner of: its patch
// has no side to spare) at the midpoint of its inner edge, with the triangle across that edge,
// where that triangle's third vertex is not on the ear's side: the ear's middle vertex then has
// two triangles, with a vertex inside the patch, and the ear is no longer flat in the
// parameterization (a flat ear's middle vertex lies off every chart's surface, about a triangle's
// height away, however finely the chart samples it). A triangle across with all its vertices on
// the side (a strip of rim triangles) is left: the new vertex would lie on the side's line in the
// polygon, and the map would collapse there. The surface is the same; the layout gains a vertex
// and two triangles an ear. Records the changes in *record; returns the ears split.
uint32_t splitOpenSideEars(PatchLayout& layout, EarSplits* record);

// Cuts patch `patch` along the shortest path of interior edges (through interior vertices only)
// between its corners i and j, which must not be adjacent (2 <= (j - i) mod n <= n - 2). The
// part with sides i..j-1 keeps the patch's index (its side 0 is the old side i); the other part
// is appended as a new patch (its side 0 is the old side j). Both get the cut as their last
// side, linked to each other; every neighbour's links follow. Returns false, leaving the layout
// unchanged, when no such path exists or a part would not be a disk.
bool splitPatchAtCorners(PatchLayout& layout, uint32_t patch, uint32_t i, uint32_t j);

// Makes the k-th vertex of side `side` of patch `patch` (0 < k < last) a corner: the side becomes
// two sides, and so does the neighbour's side across it. Returns false, unchanged, when k is not
// an inner vertex of the side or either patch would get more than maxSides sides.
bool insertCorner(PatchLayout& layout, uint32_t patch, uint32_t side, uint32_t k, uint32_t maxSides = 8);

// In the sides quad layout, a corner where only two patches meet (as evenSides makes them), away
// from the border, where neither patch starts spokes has one quad of each: two charts meet there,
// their corner texels span the surface's full turn flat and coincide. twoQuadCorners counts such
// corners; alignSpokes rotates patches of 6 or more sides (rotatePatchSides) so that every such
// corner starts spokes in one of its patches where some choice of pairings allows it (solved
// exactly, as 2-SAT), else so that as many as a greedy pass finds do, and returns the count left.
// With `only`, just those patches rotate. rotationFoldsNoCorner: whether rotating patch p by one
// leaves no more such corners at its corners (the layout is left as it was).
uint32_t twoQuadCorners(const PatchLayout& layout);
uint32_t alignSpokes(PatchLayout& layout, const std::vector<uint32_t>& only = {});
// alignSpokes, then, while such corners are left, gives one of a corner's two patches a corner in
// the middle of both its sides there (both shared with the other patch, which so gains two, and
// every side count stays even), kept where alignSpokes then leaves fewer. A 4-sided patch wrapped
// by one neighbour along three sides, as evening can leave it, has two such corners in a row that
// no pairing serves; with 6 sides it starts spokes at one of them. Returns the corners added and
// the two-chart corners left.
struct MendCornersResult {
  uint32_t corners = 0;
  uint32_t left = 0;
};
MendCornersResult mendTwoChartCorners(PatchLayout& layout, uint32_t maxSides = kMaxPatchSides);
bool rotationFoldsNoCorner(PatchLayout& layout, uint32_t p);

// Rotates the sides of patch p so that old side k becomes side 0 (the neighbours' links follow).
// The patch and its sampling are the same; only which corners its quads pair differs in the sides
// quad layout.
void rotatePatchSides(PatchLayout& layout, uint32_t p, uint32_t k);

// In the sides quad layout a hole bordered by only two sides is two chart edges between the same
// two corners, and at a chart's coarsest level (its corners alone) they coincide: the hole closes.
// Gives each such hole two more corners, on its longest side at a third and two thirds of its arc
// length (its patch keeps its side count's parity), when that side has 3 or more edges and its
// patch room for two more sides. Returns the corners made.
uint32_t splitTwoSidedHoles(PatchLayout& layout, uint32_t maxSides = kMaxPatchSides);

// Makes every patch's side count even, as the sides quad layout needs (atlas/mesh/resample.h), by
// making inner side vertices corners (insertCorner, the vertex nearest the side's arc-length
// middle, on the longest side that can take one): first on sides shared by two odd patches (one
// corner mends both), then on open sides (it mends its patch alone), then along the shortest
// chain of shared sides from an odd patch to another odd patch or to a patch with an open side
// (each patch between gains two corners). No patch passes maxSides. With `within` non-empty, only
// those patches change sides (their neighbours' links still follow). Returns the corners made and
// the patches left odd (0 unless no chain was found).
struct EvenSidesResult {
  uint32_t corners = 0;
  uint32_t oddLeft = 0;
};
EvenSidesResult evenSides(PatchLayout& layout, const std::vector<uint32_t>& within = {},
                          uint32_t maxSides = kMaxPatchSides);

// Splits, at its midpoint, the one edge of every side of `patches` that has no inner vertex: the
// triangle on either side of it becomes two (the surface stays the same), and the side, with the
// neighbour's across it, gains the midpoint as an inner vertex that evenSides can make a corner.
// Sides of zero length, and joins that are not reversed, are left as they are. Returns the edges
// split.
uint32_t splitSingleEdgeSides(PatchLayout& layout, const std::vector<uint32_t>& patches);

// The patches within `reach` links (shared sides) of the patches `from`, them included, sorted.
std::vector<uint32_t> patchesNear(const PatchLayout& layout, const std::vector<uint32_t>& from, uint32_t reach);

// The first of patch p's triangles with layout vertex v as a corner; ~0u if none has it.
uint32_t patchTriangleAt(const PatchLayout& layout, uint32_t p, uint32_t v);

// Splits `patch` by a cut through a vertex of layout triangle `triangle` (where its charts fold):
// of the shortest interior paths from that vertex to the boundary, the pair (or, from a boundary
// vertex, the single path) whose length is smallest relative to the smaller part's perimeter, such
// that both parts get 3..maxSides sides. Ends of the cut that are not corners become corners
// (insertCorner, so the neighbours there gain a side, within maxSides). Returns false if no cut
// qualifies (the layout may then have gained a corner, still valid).
bool splitPatchThrough(PatchLayout& layout, uint32_t patch, uint32_t triangle, uint32_t maxSides = 8);

// The vertex of `patch` farthest from its boundary (shortest paths along its edges; of equally far
// ones the lowest id), ~0u for a patch without inner vertices.
uint32_t deepestPatchVertex(const PatchLayout& layout, uint32_t patch);

// Splits `patch` by a cut through its deepest vertex (deepestPatchVertex) whose ends lie at least a
// quarter of the perimeter apart on both sides, under splitPatchThrough's rules otherwise. Where a
// patch closes round a tip (a tube closed at one end), this cuts it from the tip down both sides,
// where a cut between boundary points would run along the rim and a cut through the tip to its
// nearest boundary points would cut a sliver off. Returns false if no cut qualifies.
bool splitPatchFromDeepest(PatchLayout& layout, uint32_t patch, uint32_t maxSides = 8);

// Halves `patch`: of the shortest interior paths between boundary vertices (as splitPatchAtNeck
// takes them), the one whose length is smallest against the smaller part's perimeter among those
// that leave at least a quarter of the border on either side, so that neither part is a sliver;
// parts with fewer than minPartEdges border edges do not count. Both parts and any neighbour that
// gains a corner keep 3..maxSides sides. False if none qualifies (the layout may then have gained
// a corner, still valid).
bool halvePatch(PatchLayout& layout, uint32_t patch, uint32_t maxSides = 8, uint32_t minPartEdges = 0);

// Splits `patch` at its best neck: of the shortest interior paths between boundary vertices (at
// most 96 start vertices, spread evenly), the one whose length is smallest against the smaller
// part's perimeter, a new corner at an end costing a factor 1.25; both parts and any neighbour
// that gains a corner must keep 3..8 sides. Falls back to the best corner-to-corner cut. Returns
// false if nothing could be split.
bool splitPatchAtNeck(PatchLayout& layout, uint32_t patch);

struct ChartRepairOptions {
  // Rounds of each of the two repairs (see repairCharts); 0: none.
  uint32_t rounds = 2;
  // The largest sampling error a chart may keep (ImageQuality::sampleError, in the input's
  // units); 0: flips only.
  double maxSampleError = 0.0;
  // Stop once this many layout triangles have been parameterized again (about that many
  // triangles' worth of resampling time).
  uint64_t workBudget = ~uint64_t(0);
  // layoutVertexNormals(layout), if the caller holds them (positions and triangles never change in
  // a repair); computed once by the repair otherwise.
  const std::vector<glm::dvec3>* normals = nullptr;
  // If set, the trials' and rounds' parameterizations are taken from it where a patch is alike,
  // and put there (ResampleReuse::params): a neighbour that a trial cut gave a corner, and the
  // cut's parts, are parameterized once for the trial, the round that keeps the cut and the
  // resamplings after the repair. The charts are the same with it or without it.
  ParamCache* params = nullptr;
};

struct ChartRepairStats {
  uint32_t rounds = 0;  // resampling rounds after the first
  uint32_t patchesSplit = 0;
  uint32_t patchesUnsplit = 0;         // patches of the last round still to repair that no split helped
  uint32_t flippedTexelsFirst = 0;     // flipped texels of the first resampling
  double sampleErrorFirst = 0.0;       // largest sampling error of the first resampling
  uint32_t patchesOverErrorFirst = 0;  // patches of the first resampling over maxSampleError
  bool stoppedForMemory = false;       // mayGrow said no before the repair was done
  // Layout triangles parameterized again (a patch once per resampling of it): by whole rounds,
  // and by patch trials (with the rounds' closing resamplings).
  uint64_t trianglesWholeRounds = 0, trianglesTrials = 0;
  bool stoppedForWork = false;  // the work budget ran out before the repair was done
};

// Two repairs of up to repair.rounds rounds each, from `set`, the resampling of `layout`, of the
// patches whose charts fold (flipped texels) or sample the surface too coarsely (a chart's
// sampling error over repair.maxSampleError): a patch is judged by its flipped texels first,
// then by how far its errors exceed the bound. Whole rounds: every such patch is split
// (splitPatchAtNeck, else splitPatchThrough the fold or the worst vertex), the round kept only if
// the changed patches get better. Then patch by patch: the split through the fold (or worst
// vertex) is kept if it makes the patches it changes better, else the neck split if it does not
// make them worse; others are undone. Each repair ends at the first round that keeps nothing.
// Only patches a round changes are parameterized again (ResampleReuse), so the result is bit for
// bit a full resampling of the final layout. `layout` ends as the layout of the returned set.
// mayGrow, if given, is asked before every round and batch of cuts (each adds charts and working
// memory); once it says no, the repair stops there (stats->stoppedForMemory), with a valid
// layout and its charts. Likewise once the triangles parameterized again reach
// repair.workBudget (stats->stoppedForWork): the repair's time is about that of parameterizing
// so many triangles, so a budget of k times the layout's triangles bounds it by about k first
// resamplings. The result depends on neither the thread count nor the machine.
GeometryImageSet repairCharts(PatchLayout& layout, GeometryImageSet set, const ResampleOptions& options,
                              const ChartRepairOptions& repair, ChartRepairStats* stats = nullptr,
                              const std::function<bool()>& mayGrow = {});

// resampleLayout, then repairCharts.
GeometryImageSet resampleAndRepair(PatchLayout& layout, const ResampleOptions& options,
                                   const ChartRepairOptions& repair = {}, ChartRepairStats* stats = nullptr);

}  // namespace gimlod
