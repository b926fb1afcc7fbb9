// Quadrangulation and resampling of a chart layout into seamless geometry images. Each patch of
// the layout's n-gon parameterization (atlas/mesh/patch_param.h) is cut into quads around its
// centre, each mapped from the unit square bilinearly, in one of two ways (QuadLayout):
//   sides: each quad has two whole patch sides as edges, (corner 2j+1, corner 2j+2, centre,
//     corner 2j) for j < n/2, and a 4-sided patch is one quad; the patches must have an even number
//     of sides (evenSides in atlas/mesh/layout_refine.h makes them so). About n/2 charts a patch.
//   kites: each side is halved at its midpoint and quad i is the kite (corner i, midpoint of side i,
//     patch centre, midpoint of side i-1). n charts a patch, for any n.
// Position, normal and colour are sampled into (2^k+1)^2 images. Seams: every patch side is
// sampled once, by arc length along its 3D polyline in one canonical direction, and written into
// both patches; corners, side midpoints and patch centres are single values shared by every quad
// that meets there; the centre spokes inside a patch are sampled once and written into both quads.
// So charts that share an edge hold bit-identical samples there, and, since pyramid levels are
// 2^k+1 subsamplings, at every level.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5 (quadrangulate, resample); Purnomo, Cohen,
// Kumar, "Seamless Texture Atlases", SGP 2004.
#pragma once

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <limits>
#include <filesystem>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include "atlas/mesh/patch_layout.h"
#include "atlas/mesh/patch_param.h"
#include "core/atlas_format.h"

namespace gimlod {

class ChartSpill;
class ParamGate;

// How a patch is cut into quad charts (see above).
enum class QuadLayout : uint8_t { kKites, kSides };

// The quad charts of a patch with `sides` sides: kites n; sides n / 2, or 1 for n = 4. Throws
// std::invalid_argument for an odd n in the sides layout.
uint32_t patchQuadCount(uint32_t sides, QuadLayout quads);

// How a quad chart's unit square maps into its quad of the patch's domain. Both put the border
// where the bilinear map does (every edge is straight and evenly sampled in the domain), so the
// border samples, and the seams, are the same.
//   bilinear: the bilinear map of the quad's corners.
//   stretch: the patch's triangles clipped to the quad and mapped onto the square with the least
//     stretch (mapDiskOntoDomain in atlas/mesh/patch_param.h). The bilinear map of a quad far from
//     a square (a sides quad of a 10- or 12-sided patch has an angle near 150 degrees) adds its own
//     stretch to the parameterization's, and the parameterization, which is made on the patch's
//     polygon, does not see it; mapped this way, the stretch minimized is the chart's own.
//     A quad whose map cannot be made (a degenerate clip) keeps the bilinear map.
//   folding: bilinear, and stretch for the charts that fold (flipped texels) under the bilinear map,
//     kept where they fold less. Charts may mix maps since their borders are the same.
enum class QuadMap : uint8_t { kBilinear, kStretch, kFolding };

struct ResampleOptions {
  uint32_t chartSize = 513;     // samples per quad chart side; must be 2^k + 1 with k >= 1
  uint32_t threads = 0;         // worker threads for the per-patch work; 0 = all hardware threads
  ParamOptions param;           // per-patch parameterization
  ChartSpill* spill = nullptr;  // if set, every chart's samples go there once it is measured
  QuadLayout quads = QuadLayout::kKites;
  QuadMap quadMap = QuadMap::kBilinear;
  // Inner samples round flipped texels slide over the surface, through the parameterization, to
  // where their texels agree best with the input faces, kept where fewer texels fold (the border,
  // and so the seams, do not move; see resampleLayout).
  bool unfold = true;
  // The unfolding leaves every slid sample at least this far from the samples within two texels
  // of it (in the input's units; 0: any distance above none): two lattice steps of the coding's
  // positions, so that settling them on it never merges two samples.
  double minSampleGap = 0.0;
  // Charts of fewer samples a side than this also count, in their sampling error, how far the
  // input vertices of their shared sides lie from the polyline through the side's samples (the
  // chords they cut across a curved or kinked side); 0: none do.
  uint32_t chordsBelow = 0;
  // If set, each patch's parameterization and sampling wait there until their working memory
  // fits beside those running (see ParamGate).
  ParamGate* gate = nullptr;
};

// Quality of a sampled image, seen as a map from the unit square to the sampled surface through
// its texel quads (two triangles each: (u,v) (u+1,v) (u+1,v+1) and (u,v) (u+1,v+1) (u,v+1)).
// Stretch as in ParamQuality (normalized per chart; 1 is best).
struct ImageQuality {
  double stretchL2 = 1.0;
  double stretchLinf = 1.0;
  // Texel quads whose 3D normal (cross of the diagonals) opposes every input face under their
  // corners (the face a corner is located in; for a sample on a patch side, the patch's face
  // along that side; the interpolated vertex normals where no face is known): folds the atlas
  // itself makes. A texel that agrees with one of its faces follows the input where the input
  // turns by more than a right angle within one texel (a fin), and is not counted.
  uint32_t flippedTexels = 0;
  // Texel quads whose 3D normal opposes the mean of their 4 interpolated vertex normals. This
  // also counts texels that faithfully follow a folded input triangle (one facing against its
  // own vertex normals, as scans have), so it is >= flippedTexels less such texels.
  uint32_t texelsAgainstNormals = 0;
  uint32_t degenerateTexels = 0;  // texel quads of (near) zero 3D area
  uint32_t texelsUnfolded = 0;    // flipped texels the unfolding (ResampleOptions::unfold) mended
  // Inner samples the unfolding slid past their chart's quad of the domain (by less than a texel,
  // next to the border, where a fold runs along it): the chart overlaps its neighbour there.
  uint32_t samplesPastQuad = 0;
  // The largest distance from an input vertex to the chart's surface (its texels as the renderer
  // triangulates them) round the vertex's own chart coordinates (the 3 x 3 texels there, 5 x 5 in
  // a chart whose samples the unfolding slid): the
  // sampling error the parameterization's texel sizes leave, an upper bound of the vertex's
  // distance to the atlas. Vertices of the patch's interior and open sides count; those of its
  // shared sides (sampled by arc length alike in both patches) are left to the fidelity figure.
  // In the input's units; the worst vertex is a layout vertex id (~0u when none).
  double sampleError = 0.0;
  uint32_t sampleErrorVertex = ~0u;
  double area3D = 0.0;  // surface area of the sampled grid
  // The shortest side of a texel (in the input's units; infinite without texels): how far apart
  // the closest neighbouring samples lie, where the map squeezes the surface most.
  double shortestTexelSide = std::numeric_limits<double>::infinity();
};

// One quad chart: a (chartSize)^2 row-major image, row = v, u = column. Each edge's
// counter-clockwise parameter (core/atlas_format.h Edge) runs along the patch's boundary order.
// Kite i: (0,0) corner i, (1,0) midpoint of side i, (1,1) patch centre, (0,1) midpoint of side
// i-1; bottom = first half of side i, right = midpoint i -> centre, top = centre -> midpoint i-1,
// left = second half of side i-1.
// Sides quad j (n >= 6): (0,0) corner 2j+1, (1,0) corner 2j+2, (1,1) centre, (0,1) corner 2j;
// bottom = side 2j+1, left = side 2j, right and top the spokes to corners 2j+2 and 2j.
// Sides quad of a 4-sided patch: (0,0) .. (0,1) corners 0..3, edge e = side e.
struct GeometryImage {
  uint32_t patch = 0;                       // PatchLayout patch
  uint32_t quad = 0;                        // i, 0..n-1 within the patch
  std::vector<glm::vec3> positions;         // chartSize^2
  std::vector<PackedNormal> normals;        // chartSize^2, unit normals (packNormal)
  std::vector<glm::u8vec4> colours;         // chartSize^2, or empty if the layout has none
  std::array<RootNeighbour, 4> neighbours;  // by Edge; chart = index into GeometryImageSet
  ImageQuality quality;
  std::vector<uint32_t> foldTriangles;  // layout triangles under flipped texels (<= 8)
  // [k - 1]: the flipped texels (ImageQuality::flippedTexels) of the image's pyramid level k >= 1,
  // every 2^k-th of its samples a side.
  std::vector<uint32_t> flippedAtLevel;
  int64_t spilled = -1;  // where a ChartSpill holds the samples; -1: here
  // The pyramid level of the set's chart size that the image holds: ((chartSize - 1) >> level) + 1
  // samples a side (charts sampled at their own size; core/atlas_format.h ChartInfo::finestLevel).
  uint8_t level = 0;

  // The samples a side of this image in a set of charts of chartSize^2 samples.
  uint32_t side(uint32_t chartSize) const { return ((chartSize - 1) >> level) + 1; }
  // Whether the chart's samples exist, here or in a spill.
  bool hasSamples(uint32_t chartSize) const {
    return spilled >= 0 || positions.size() == size_t(side(chartSize)) * side(chartSize);
  }
};

// A file that charts' samples are moved to once they are measured, so that a large layout's
// geometry images are not all held in memory until they are written: refinement (which moves
// charts, reads only their figures and resamples a few patches again) and writing (which reads
// each back in turn) work the same on spilled charts. Samples replaced by a later resampling stay
// in the file, unread. Each record starts with its image's side in samples, so images of
// different sizes share one spill. put and get may run on several threads at once.
class ChartSpill {
 public:
  // Creates (or truncates) the file. Throws InputError naming it when it cannot.
  ChartSpill(const std::filesystem::path& file, bool colours);
  ~ChartSpill();  // closes and removes the file
  ChartSpill(const ChartSpill&) = delete;
  ChartSpill& operator=(const ChartSpill&) = delete;
  // Appends the image's samples (s^2 positions and normals, s = 2^k + 1, and colours if the spill
  // has them) and frees them. Throws std::invalid_argument when they do not match, InputError
  // naming the file when it cannot be written (a full disk).
  void put(GeometryImage& image);
  // Reads a spilled image's samples back into it (spilled = -1 after); no-op for one held here.
  void get(GeometryImage& image) const;
  uint64_t bytes() const { return end_; }

 private:
  std::filesystem::path file_;
  bool colours_;
  int fd_ = -1;
  std::atomic<uint64_t> end_{0};
};

struct PatchResampleStats {
  ParamQuality paramInitial;  // the mean-value embedding
  ParamQuality param;         // after stretch reduction
  uint32_t stretchIterations = 0;
  uint32_t firstChart = 0;  // charts [firstChart, firstChart + quads) belong to this patch
  uint32_t sides = 0;
  uint32_t quads = 0;
};

struct GeometryImageSet {
  uint32_t chartSize = 0;
  std::vector<GeometryImage> charts;  // patch by patch, quad by quad
  std::vector<PatchResampleStats> patches;
  ParamQuality paramInitial;  // all patches combined (combineQuality)
  ParamQuality param;
  ImageQuality image;                   // all charts combined
  uint64_t trianglesParameterized = 0;  // of the patches this resampling parameterized (not reused)
  double seconds = 0.0;
};

// Per patch, the chart id of its quad 0 (the sum of the quads of the patches before it): quad i
// of patch p is chart offsets[p] + i.
std::vector<uint32_t> quadChartOffsets(const PatchLayout& layout, QuadLayout quads = QuadLayout::kKites);

// The four neighbours of every quad chart (by Edge): inside a patch from the quads' structure,
// across patches from PatchSide neighbourPatch / neighbourSide / reversed. Open sides give
// chart = -1. Throws std::invalid_argument("quadNeighbours: ...") on side links that are not
// reciprocal or whose vertex runs do not match, or an odd patch in the sides layout.
std::vector<std::array<RootNeighbour, 4>> quadNeighbours(const PatchLayout& layout,
                                                         QuadLayout quads = QuadLayout::kKites);

// Parameterizes every patch and resamples its quads (patches in parallel). Normals are the
// layout's area-weighted vertex normals, interpolated and normalized; colours are interpolated
// when the layout has them. Throws std::invalid_argument on an invalid chartSize, a malformed
// patch (see parameterizePatch) or bad side links (see quadNeighbours).
GeometryImageSet resampleLayout(const PatchLayout& layout, const ResampleOptions& options = {});

// The layout's unit area-weighted vertex normals (zero where undefined), as resampleLayout
// interpolates them. They depend on positions and triangles only, which layout refinement
// (atlas/mesh/layout_refine.h) never changes, so a refinement loop computes them once.
std::vector<glm::dvec3> layoutVertexNormals(const PatchLayout& layout);

// Patch parameterizations kept from one resampling of a layout to the next, so that a patch
// resampled at another chart size, or again after a cut elsewhere left it as it was
// (patchParamAlike: its triangles and sides unchanged), is parameterized once. A patch's
// parameterization depends on nothing else but the options (the quad layout's paired polygon),
// which one cache is used with throughout, so its charts are bit for bit those of a fresh
// parameterization. Several versions of a patch may be kept (a trial cut gives a neighbour a
// corner, and the trial may be undone). Holds at most maxBytes of parameterizations (about 8
// bytes a triangle: the coordinates): past it, the least recently used are dropped. find and put
// may run on several threads at once; which entries are kept then depends on their order, the
// charts never do. An entry knows its patch's triangles by their count and a 128-bit digest of
// the list (patchDigest), not by a copy (4 bytes a triangle more), so that the 18.7M-triangle
// sphere's first resampling (about 150 MB) leaves room, within an eighth of 2 GiB, for the
// versions the repair and the sizing add. Two lists of one patch that differ share a digest with
// a chance of about 2^-128.
class ParamCache {
 public:
  explicit ParamCache(uint64_t maxBytes) : maxBytes_(maxBytes) {}
  // Patch p's parameterization if one was put for a patch alike; null otherwise. An entry keeps
  // no local vertex and triangle lists (they are the patch's triangles, numbered as
  // parameterizePatch numbers them): they are made again from `layout`, whose patch p is `patch`.
  std::shared_ptr<const PatchParameterization> find(const PatchLayout& layout, const Patch& patch, uint32_t p) const;
  // Keeps pp as the parameterization of patch p as `patch` is now (in place of one for a patch
  // alike), dropping the least recently used past maxBytes; nothing is kept if pp alone is larger.
  void put(const Patch& patch, uint32_t p, std::shared_ptr<const PatchParameterization> pp);
  uint64_t hits() const { return hits_; }
  uint64_t bytes() const;

 private:
  struct Entry {
    uint32_t p = 0;
    size_t triangles = 0;              // the patch's triangle count
    std::array<uint64_t, 2> digest{};  // and patchDigest of its list
    std::vector<PatchSide> sides;
    std::shared_ptr<const PatchParameterization> pp;
    uint64_t bytes = 0;
  };
  using Order = std::list<Entry>;
  // Patch p's entry for a patch alike (its triangles' digest `digest`), made the most recently
  // used; end() if none. The caller holds mutex_.
  Order::iterator entryFor(const Patch& patch, const std::array<uint64_t, 2>& digest, uint32_t p) const;
  mutable std::mutex mutex_;
  mutable Order order_;  // most recently used first
  std::unordered_multimap<uint32_t, Order::iterator> byPatch_;
  uint64_t bytes_ = 0;
  const uint64_t maxBytes_;
  mutable std::atomic<uint64_t> hits_{0};
};

// Estimated working memory of parameterizing a patch of `triangles` triangles (n = triangles / 2
// vertices), mostly its sparse LU's factors: their fill under the AMD ordering is 5 to 7 n log2 n
// entries (the spheres' patches of 13k to 335k vertices), at about 11 bytes an entry in single
// precision and 17 in double with the supernodes' indices (ParamOptions::singlePrecisionFrom),
// taken as 72 or 110 n log2 n bytes; and the local arrays (weights, matrices, coordinates),
// about 640 bytes a vertex.
uint64_t paramWorkingBytes(uint64_t triangles, uint32_t singlePrecisionFrom);

// Lets patches be parameterized and sampled at once only while their working memory (mostly
// paramWorkingBytes) fits in a budget together; one always runs, whatever its estimate, so a
// budget of 0 runs them one at a time. Waiting threads sleep; Holds may be taken and given back
// on several threads at once. On two cores, two patches of the 18.7M-triangle sphere do not fit
// beside the layout within 2 GiB, so the gate trades time for memory there.
class ParamGate {
 public:
  explicit ParamGate(uint64_t budget) : budget_(budget) {}
  ParamGate(const ParamGate&) = delete;
  ParamGate& operator=(const ParamGate&) = delete;

  // Held working memory, given back when it goes out of scope.
  class Hold {
   public:
    Hold(ParamGate& gate, uint64_t bytes);
    ~Hold();
    Hold(const Hold&) = delete;
    Hold& operator=(const Hold&) = delete;

   private:
    ParamGate& gate_;
    const uint64_t bytes_;
  };

  uint64_t budget() const { return budget_; }
  // Whether a hold of `bytes` would run now without waiting (a hint: others may take or give
  // back holds at once).
  bool fitsNow(uint64_t bytes);
  // Holds that had to wait for others to be given back.
  uint64_t waits() const { return waits_; }

 private:
  std::mutex mutex_;
  std::condition_variable freed_;
  uint64_t held_ = 0;
  uint32_t running_ = 0;
  const uint64_t budget_;
  std::atomic<uint64_t> waits_{0};
};

// Whether two versions of a patch parameterize identically: the same triangles in the same order,
// and the same sides (vertex runs, and which are open).
bool patchParamAlike(const Patch& a, const Patch& b);
// A 128-bit digest of a patch's triangle list, in its order (two independent 64-bit hashes).
std::array<uint64_t, 2> patchDigest(const Patch& patch);

// What a resampling of a refined layout may take from earlier resamplings of the same surface.
struct ResampleReuse {
  const std::vector<glm::dvec3>* normals = nullptr;  // layoutVertexNormals(layout), if known
  // Earlier resamplings and the patches each was made from, searched in order. Patch p takes
  // the charts of patch p of the first source whose patch p samples identically (the same
  // triangles, the same side vertex runs, and each side sampled from the same end: the same
  // owner and direction) and whose charts for it are not empty: they are moved out of that
  // source, and only their neighbours are set anew. A patch's charts depend on nothing else, so
  // the result is bit for bit the full resampling's.
  struct Source {
    const std::vector<Patch>* patches = nullptr;
    GeometryImageSet* set = nullptr;
  };
  std::vector<Source> earlier;
  // If set (one flag per patch), only the flagged patches are resampled; the others' charts
  // keep no samples and default quality, so the set's figures are those of the flagged patches.
  const std::vector<uint8_t>* only = nullptr;
  // If set, parameterizations are taken from it where a patch is alike, and put there.
  ParamCache* params = nullptr;
};

// Whether two versions of the patch at index p of a layout sample identically (see
// ResampleReuse): the same triangles, the same side runs, each side sampled from the same end.
bool patchSamplesAlike(const Patch& a, const Patch& b, uint32_t p);

// resampleLayout, reusing what `reuse` offers.
GeometryImageSet resampleLayout(const PatchLayout& layout, const ResampleOptions& options, const ResampleReuse& reuse);

// Measures one image (positions and float unit normals, chartSize^2 each). flippedAt, if given,
// receives the sample index of the (0,0) corner of every flipped texel. faceNormals, if given, are
// the unit normals of the input faces under the samples (zero where none); without them a texel
// is flipped when it opposes the vertex normals.
ImageQuality measureImage(const std::vector<glm::vec3>& positions, const std::vector<glm::vec3>& normals,
                          uint32_t chartSize, std::vector<uint32_t>* flippedAt = nullptr,
                          const std::vector<glm::vec3>* faceNormals = nullptr);

// One flag per patch (patches of them): whether one of its charts in set has a sampling error over
// maxError.
std::vector<uint8_t> patchesOverSampleError(const GeometryImageSet& set, size_t patches, double maxError);

// Combines per-chart figures: 3D-area-weighted RMS of the per-chart L2, max Linf, summed counts.
// note: each chart is normalized by its own area, so imbalance between charts (a large chart
// gets as many texels as a small one) is not part of these figures.
ImageQuality combineImageQuality(const std::vector<ImageQuality>& parts);

}  // namespace gimlod
