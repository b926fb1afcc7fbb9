#include "pipeline/sharded_build.h"

#include <algorithm>
#include <charconv>
#include <chrono>
#include <fstream>
#include <memory>
#include <numeric>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <tbb/global_control.h>
#include <unistd.h>
#include <xxhash.h>

#include "atlas/terrain/imagery.h"
#include "atlas/terrain/scratch_raster.h"
#include "atlas/terrain/terrain_windowed.h"
#include "core/atlas_format.h"
#include "core/stage_meter.h"
#include "hierarchy/hierarchy.h"
#include "pipeline/build_report.h"
#include "pipeline/terrain_build.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace gimlod {
namespace {

constexpr const char* kPlanName = "plan.json";
constexpr const char* kShardRecordName = "shard.json";
constexpr const char* kShardQuadtrees = "quadtrees.bin";
constexpr const char* kScratchName = "dem.scratch";
constexpr const char* kScratchIndexName = "dem.scratch.index";
constexpr const char* kImageryCoarseName = "imagery/coarse.bin";
constexpr const char* kPlanFormat = "gimlod-shard-plan";
constexpr const char* kShardFormat = "gimlod-shard";
constexpr int kShardFormatVersion = 1;

std::string hostName() {
  char name[256] = {};
  if (::gethostname(name, sizeof(name) - 1) != 0) return "unknown";
  return name;
}

double cpuSeconds() {
  rusage u{};
  ::getrusage(RUSAGE_SELF, &u);
  auto sec = [](const timeval& t) { return double(t.tv_sec) + 1e-6 * double(t.tv_usec); };
  return sec(u.ru_utime) + sec(u.ru_stime);
}

// A step's figures, from its start.
ShardStepStats stepStats(std::chrono::steady_clock::time_point t0, double cpu0) {
  ShardStepStats s;
  s.seconds = secondsSince(t0);
  s.cpuSeconds = cpuSeconds() - cpu0;
  s.peakRssBytes = peakResidentBytes();
  s.host = hostName();
  return s;
}

json stepJson(const ShardStepStats& s) {
  return {{"seconds", s.seconds}, {"cpu_seconds", s.cpuSeconds}, {"peak_rss_bytes", s.peakRssBytes}, {"host", s.host}};
}

ShardStepStats stepFromJson(const json& j) {
  ShardStepStats s;
  s.seconds = j.value("seconds", 0.0);
  s.cpuSeconds = j.value("cpu_seconds", 0.0);
  s.peakRssBytes = j.value("peak_rss_bytes", uint64_t{0});
  s.host = j.value("host", std::string());
  return s;
}

// An XXH3 checksum of bytes given in pieces, as 16 hex digits.
class Checksum {
 public:
  Checksum() : state_(XXH3_createState(), &XXH3_freeState) { XXH3_64bits_reset(state_.get()); }
  void add(const void* data, size_t bytes) { XXH3_64bits_update(state_.get(), data, bytes); }
  std::string hex() const { return fmt::format("{:016x}", XXH3_64bits_digest(state_.get())); }

 private:
  std::unique_ptr<XXH3_state_t, decltype(&XXH3_freeState)> state_;
};

// XXH3 of a file's bytes, read in pieces.
std::string fileChecksum(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string() + ": cannot open it");
  Checksum sum;
  std::vector<char> piece(size_t{4} << 20);
  while (in) {
    in.read(piece.data(), std::streamsize(piece.size()));
    sum.add(piece.data(), size_t(in.gcount()));
  }
  if (in.bad()) throw InputError(path.string() + ": cannot read it");
  return sum.hex();
}

// A file's identity: its absolute path, size and modification time.
json fileIdentity(const fs::path& file) {
  std::error_code ec;
  const fs::path path = fs::absolute(file);
  const auto bytes = fs::file_size(path, ec);
  const auto modified = fs::last_write_time(path, ec);
  return {{"path", path.string()},
          {"bytes", ec ? uint64_t{0} : uint64_t(bytes)},
          {"modified_ns",
           int64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(modified.time_since_epoch()).count())}};
}

// What a shard must share with its plan: the input's identity and every option that changes the
// atlas's bytes, the imagery's identity included (not the threads, the memory cap or the
// window-by-window choice, which do not).
json buildFingerprint(const TerrainBuildOptions& o) {
  return {{"input", fileIdentity(o.input)},
          {"options",
           {{"chart_size", o.chartSize},
            {"depth", o.depth},
            {"node_res", o.nodeRes},
            {"min_node_res", o.minNodeRes},
            {"compress", o.compress},
            {"subdataset", o.subdataset},
            {"band", o.band},
            {"spacing", o.spacing},
            {"z_scale", o.zScale},
            {"height_precision", o.heightPrecision},
            {"planet", o.planet},
            {"radius", o.planetRadius},
            {"flattening", o.planetFlattening},
            {"imagery", o.imagery.empty() ? json() : fileIdentity(o.imagery)},
            {"imagery_scale", o.imageryScaleLog2},
            {"imagery_extent", o.imageryExtent ? json(*o.imageryExtent) : json()}}}};
}

// The keys where two fingerprints differ ("input.bytes", "options.chart_size").
std::string fingerprintDifference(const json& a, const json& b) {
  std::vector<std::string> keys;
  for (const char* part : {"input", "options"})
    for (const auto& [k, v] : a.at(part).items())
      if (!b.contains(part) || !b.at(part).contains(k) || b.at(part).at(k) != v)
        keys.push_back(std::string(part) + "." + k);
  return keys.empty() ? std::string("the fingerprints differ") : fmt::format("{}", fmt::join(keys, ", "));
}

json readJsonFile(const fs::path& path, const char* format) {
  const std::vector<uint8_t> bytes = readFileBytes(path);
  json j;
  try {
    j = json::parse(bytes.begin(), bytes.end());
  } catch (const json::exception& e) {
    throw InputError(path.string() + ": invalid JSON (" + e.what() + ")");
  }
  if (!j.is_object() || j.value("format", std::string()) != format || j.value("version", 0) != kShardFormatVersion)
    throw InputError(path.string() + ": not a " + format + " file of version " + std::to_string(kShardFormatVersion));
  return j;
}

void writeJsonFile(const fs::path& path, const json& j) {
  const std::string text = j.dump(2) + "\n";
  atomicWriteFile(path, text.data(), text.size());
}

std::string shardDirName(ShardId id) { return fmt::format("shard-{}-of-{}", id.index, id.count); }

// Each chart's estimated work: its samples inside the DEM (what its quadtree measures) and 0.8 of a
// whole chart's (its file codes the whole pyramid, the grid's padding included). The weights are
// the stages' shares in a one-process build of the 5.5G-sample DEM: chart tiles 123 s for 28 whole
// charts, the hierarchy 106 s for their 5.5G samples.
std::vector<double> chartWork(const AtlasManifest& m) {
  const int64_t M = m.chartSize - 1;
  std::vector<double> work;
  for (const ChartInfo& c : m.charts) {
    const int64_t w = std::clamp<int64_t>(int64_t(m.samplesX) - c.gridX * M, 1, M + 1);
    const int64_t h = std::clamp<int64_t>(int64_t(m.samplesY) - c.gridY * M, 1, M + 1);
    work.push_back(double(w) * double(h) + 0.8 * double(M + 1) * double(M + 1));
  }
  return work;
}

json readPlan(const fs::path& area) {
  std::error_code ec;
  if (!fs::exists(area / kPlanName, ec))
    throw InputError((area / kPlanName).string() +
                     ": no plan (run `gimlod build INPUT -o ATLAS --prepare` before the shards)");
  json plan = readJsonFile(area / kPlanName, kPlanFormat);
  if (plan.value("kind", std::string()) != "terrain")
    throw InputError((area / kPlanName).string() + ": a plan of an unknown kind");
  return plan;
}

std::unique_ptr<tbb::global_control> threadLimit(uint32_t threads) {
  if (!threads) return nullptr;
  return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, threads);
}

}  // namespace

ShardId parseShardId(std::string_view text) {
  ShardId id;
  const size_t slash = text.find('/');
  auto number = [&](std::string_view s, uint32_t& out) {
    const auto r = std::from_chars(s.data(), s.data() + s.size(), out);
    return r.ec == std::errc() && r.ptr == s.data() + s.size() && !s.empty();
  };
  if (slash == std::string_view::npos || !number(text.substr(0, slash), id.index) ||
      !number(text.substr(slash + 1), id.count) || id.count == 0 || id.count > kMaxShards || id.index >= id.count)
    throw InputError(fmt::format("{} \"{}\" must be I/N with 0 <= I < N <= {} (shards count from 0)",
                                 optionRef("shard"), text, kMaxShards));
  return id;
}

fs::path shardArea(const fs::path& atlas) {
  fs::path a = fs::absolute(atlas);
  if (a.filename().empty()) a = a.parent_path();
  return a.parent_path() / (a.filename().string() + ".shards");
}

std::vector<uint32_t> shardCharts(const std::vector<double>& work, ShardId id) {
  // The least largest run: a binary search over the bound, each tried greedily.
  auto runsUnder = [&](double bound) {
    uint32_t runs = 1;
    double sum = 0.0;
    for (double w : work) {
      if (sum + w > bound && sum > 0.0) ++runs, sum = 0.0;
      sum += w;
    }
    return runs;
  };
  double lo = work.empty() ? 0.0 : *std::max_element(work.begin(), work.end());
  double hi = std::accumulate(work.begin(), work.end(), 0.0);
  for (int i = 0; i < 100 && hi - lo > 1e-9 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (runsUnder(mid) <= id.count ? hi : lo) = mid;
  }
  // The runs under that bound, greedily from the first chart: shard i takes run i.
  std::vector<uint32_t> out;
  uint32_t run = 0;
  double sum = 0.0;
  for (uint32_t c = 0; c < work.size(); ++c) {
    // A new run past the bound, or where the charts left are no more than the runs left.
    const bool fewLeft = work.size() - c <= size_t(id.count - 1 - std::min(run, id.count - 1));
    if (sum > 0.0 && (sum + work[c] > hi || fewLeft)) ++run, sum = 0.0;
    sum += work[c];
    if (run == id.index) out.push_back(c);
  }
  return out;
}

namespace {

// The prepare's imagery: the manifest's imagery fields (the coverage is the merge's) and the plan's.
json prepareImagery(const TerrainBuildOptions& o, const DemRaster& dem, AtlasManifest& m) {
  const ImagerySource imagery(dem, o.input, imageryOptions(o));
  m.imagery.present = true;
  m.imagery.scaleLog2 = imagery.scaleLog2();
  m.imagery.source = fs::absolute(o.imagery).string();
  m.imagery.coverage = 0.0;
  for (ChartInfo& c : m.charts) c.imageryFile = imageryFileName(c.id);
  for (const std::string& warning : imagery.warnings()) spdlog::warn("{}: {}", o.imagery.string(), warning);
  return {{"width", imagery.width()},
          {"height", imagery.height()},
          {"scale", imagery.scaleLog2()},
          {"resampling", imagery.resampling()}};
}

// The shard charts' imagery in `dir`: partial chart files (the levels below the coarse level) and
// their coarse level's samples (kImageryCoarseName); the figures its record keeps.
json writeShardImagery(const TerrainBuildOptions& o, const WindowedTerrainOptions& wo, const AtlasManifest& m,
                       const std::vector<uint32_t>& charts, const fs::path& dir) {
  const DemSource source(o.input, terrainDemOptions(o));
  ImagerySource imagery(source.info(), o.input, imageryOptions(o));
  AtlasManifest part = m;
  ImageryWindowing windowing;
  windowing.memoryBytes = wo.memoryBytes;
  const ImageryPart written = writeImageryChartsPart(imagery, m.imagery.source, dir, part, windowing, charts);
  atomicWriteFile(dir / kImageryCoarseName, written.coarse.data(), written.coarse.size() * sizeof(PackedColour));
  return {{"covered_samples", written.stats.coveredSamples},
          {"stored_samples", written.stats.storedSamples},
          {"bytes", written.stats.bytesOnDisk},
          {"seconds", written.stats.seconds},
          {"windows", written.windows.windows},
          {"window_samples", written.windows.windowSamples},
          {"coarse_level", written.coarseLevel}};
}

// The merge's imagery: every chart's file carried on from its shard's partial file with the levels
// from the coarse level up, and the manifest's coverage. Returns the finished files' bytes and the
// samples of the levels it wrote.
ImageryWriteStats mergeImagery(const fs::path& area, const fs::path& dir, const json& plan,
                               const std::vector<ShardBuildStats>& shards, AtlasManifest& m) {
  const uint32_t coarseLevel = shardImageryTiling(m).coarseLevel;
  const uint64_t n = ((uint64_t(m.chartSize - 1) << m.imagery.scaleLog2) >> coarseLevel) + 1;
  std::vector<PackedColour> coarse(n * n * m.charts.size());
  std::vector<fs::path> partials(m.charts.size());
  uint64_t covered = 0;
  for (const ShardBuildStats& s : shards) {
    if (s.charts.empty()) continue;
    const fs::path shardDir = area / shardDirName(s.id), file = shardDir / kImageryCoarseName;
    const std::vector<uint8_t> bytes = readFileBytes(file);
    if (s.imagery.value("coarse_level", ~0u) != coarseLevel ||
        bytes.size() != s.charts.size() * n * n * sizeof(PackedColour))
      throw InputError(file.string() + ": not the coarse imagery samples of the shard's charts");
    for (size_t k = 0; k < s.charts.size(); ++k) {
      std::memcpy(coarse.data() + s.charts[k] * n * n, bytes.data() + k * n * n * sizeof(PackedColour),
                  n * n * sizeof(PackedColour));
      partials[s.charts[k]] = shardDir / m.charts[s.charts[k]].imageryFile;
    }
    covered += s.imagery.value("covered_samples", uint64_t{0});
  }
  if (covered == 0) throw InputError(m.imagery.source + ": does not overlap the DEM");
  const json& im = plan.at("imagery");
  m.imagery.coverage =
      double(covered) / (double(im.at("width").get<uint64_t>()) * double(im.at("height").get<uint64_t>()));
  return finishImageryCharts(dir, m, partials, std::move(coarse), coarseLevel);
}

}  // namespace

ShardPrepareStats prepareShards(const TerrainBuildOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  const double cpu0 = cpuSeconds();
  const TerrainBuildOptions o = plannedTerrainBuild(options);
  const auto threads = threadLimit(o.threads);
  AtlasManifest m = terrainManifest(o);
  const fs::path area = shardArea(o.output);
  StagedDirectory stage(area, kPlanName, "shard area");
  const DemSource source(o.input, terrainDemOptions(o));
  logTerrainSource(o, source.info());
  const WindowedTerrainOptions wo = windowedTerrainOptions(o);
  PreparedTerrainWindows prepared = prepareTerrainWindows(source, stage.path() / kScratchName, wo, m);
  prepared.scratch->keep(stage.path() / kScratchIndexName);
  const DemRaster& dem = prepared.result.dem;
  const json imagery = o.imagery.empty() ? json() : prepareImagery(o, dem, m);
  writeManifest(stage.path(), m);
  json plan = {{"format", kPlanFormat},
               {"version", kShardFormatVersion},
               {"kind", "terrain"},
               {"fingerprint", buildFingerprint(options)},
               {"work", chartWork(m)},
               {"read",
                {{"width", dem.width},
                 {"height", dem.height},
                 {"spacing", dem.spacing},
                 {"height_range", {dem.minHeight, dem.maxHeight}},
                 {"voids_filled", dem.voidsFilled},
                 {"void_fill_method", dem.voidFillMethod}}},
               {"scratch", {{"bytes", prepared.result.scratchBytes}, {"tile", prepared.result.scratchTile}}},
               // Every shard builds its charts in the tiles chosen here: the chart files' block order
               // follows them.
               {"chart_tile", windowChartTile(m.chartSize, m.blockIntervals, wo.memoryBytes)},
               {"imagery", imagery}};
  // The plan's id: its fingerprint, its manifest and its scratch raster's index.
  const std::vector<uint8_t> manifest = readFileBytes(stage.path() / kManifestName);
  const std::vector<uint8_t> index = readFileBytes(stage.path() / kScratchIndexName);
  const std::string head = plan["fingerprint"].dump() + plan["chart_tile"].dump();
  Checksum id;
  id.add(head.data(), head.size());
  id.add(manifest.data(), manifest.size());
  if (fs::exists(stage.path() / kChartListName)) {
    const std::vector<uint8_t> list = readFileBytes(stage.path() / kChartListName);
    id.add(list.data(), list.size());
  }
  id.add(index.data(), index.size());
  ShardPrepareStats st;
  st.plan = id.hex();
  st.charts = uint32_t(m.charts.size());
  plan["id"] = st.plan;
  st.step = stepStats(t0, cpu0);
  plan["prepare"] = stepJson(st.step);
  writeJsonFile(stage.path() / kPlanName, plan);
  stage.commit();
  return st;
}

ShardBuildStats buildShard(const TerrainBuildOptions& options, ShardId id) {
  const auto t0 = std::chrono::steady_clock::now();
  const double cpu0 = cpuSeconds();
  const fs::path area = shardArea(options.output);
  const json plan = readPlan(area);
  const json mine = buildFingerprint(options);
  if (plan.at("fingerprint") != mine)
    throw InputError(
        fmt::format("{}: the plan was made from another input or other options ({}); prepare again or "
                    "give the shard the plan's",
                    (area / kPlanName).string(), fingerprintDifference(plan.at("fingerprint"), mine)));
  const auto threads = threadLimit(options.threads);
  const AtlasManifest m = readManifest(area);
  TerrainBuildOptions o = options;
  o.chartSize = m.chartSize;
  o.depth = m.depth;
  ShardBuildStats st;
  st.id = id;
  st.charts = shardCharts(plan.at("work").get<std::vector<double>>(), id);
  spdlog::info("shard {} of {}: {} of {} charts", id.index, id.count, st.charts.size(), m.charts.size());
  StagedDirectory stage(area / shardDirName(id), kShardRecordName, "shard");
  if (!st.charts.empty()) {
    const ScratchRaster scratch(area / kScratchName, o.input, area / kScratchIndexName);
    WindowedTerrainResult r;
    r.heightPrecision = m.compression.present ? m.compression.heightPrecision : 0.0;
    WindowedTerrainOptions wo = windowedTerrainOptions(o);
    wo.chartTile = plan.at("chart_tile").get<uint32_t>();
    writeTerrainChartWindows(scratch, stage.path(), wo, m, st.charts, r);
    AtlasManifest part = m;
    part.charts.clear();
    for (uint32_t c : st.charts) part.charts.push_back(m.charts[c]);
    HierarchyStats hs;
    Hierarchy h = measureTerrainHierarchy(part, stage.path(), &hs);
    for (auto& roots : h.roots) roots = {};  // the merge takes them from the manifest
    writeHierarchy(stage.path() / kShardQuadtrees, h, true);
    st.hierarchySeconds = hs.seconds;
    if (m.imagery.present) st.imagery = writeShardImagery(o, wo, m, st.charts, stage.path());
  }
  json files = json::array();
  for (const auto& e : fs::recursive_directory_iterator(stage.path())) {
    if (!e.is_regular_file()) continue;
    const uint64_t bytes = e.file_size();
    st.bytes += bytes;
    files.push_back({{"path", fs::relative(e.path(), stage.path()).generic_string()},
                     {"bytes", bytes},
                     {"xxh3", fileChecksum(e.path())}});
  }
  std::sort(files.begin(), files.end(), [](const json& a, const json& b) { return a["path"] < b["path"]; });
  st.step = stepStats(t0, cpu0);
  writeJsonFile(stage.path() / kShardRecordName, {{"format", kShardFormat},
                                                  {"version", kShardFormatVersion},
                                                  {"plan", plan.at("id")},
                                                  {"fingerprint", mine},
                                                  {"shard", id.index},
                                                  {"of", id.count},
                                                  {"charts", st.charts},
                                                  {"files", files},
                                                  {"bytes", st.bytes},
                                                  {"hierarchy_seconds", st.hierarchySeconds},
                                                  {"imagery", st.imagery},
                                                  {"step", stepJson(st.step)}});
  stage.commit();
  return st;
}

namespace {

// The N of the shards the area holds; throws InputError when none has finished or several N have.
uint32_t shardCountIn(const fs::path& area) {
  std::vector<uint32_t> counts;
  for (const auto& e : fs::directory_iterator(area)) {
    const std::string name = e.path().filename().string();
    uint32_t i = 0, n = 0;
    if (e.is_directory() && std::sscanf(name.c_str(), "shard-%u-of-%u", &i, &n) == 2 && n > 0 &&
        shardDirName({i, n}) == name)
      counts.push_back(n);
  }
  std::sort(counts.begin(), counts.end());
  counts.erase(std::unique(counts.begin(), counts.end()), counts.end());
  if (counts.empty()) throw InputError(area.string() + ": no shard has finished; run the shards before the merge");
  if (counts.size() > 1)
    throw InputError(fmt::format("{}: shards of {} different counts ({}); give {} N", area.string(), counts.size(),
                                 fmt::join(counts, ", "), optionRef("shards")));
  return counts[0];
}

// Shard id's record, checked against the plan and its own files; the problem, or empty.
std::string checkShard(const fs::path& area, const json& plan, ShardId id, json& record) {
  const fs::path dir = area / shardDirName(id);
  std::error_code ec;
  if (!fs::exists(dir / kShardRecordName, ec))
    return fmt::format("shard {} of {} is missing ({})", id.index, id.count, dir.string());
  try {
    record = readJsonFile(dir / kShardRecordName, kShardFormat);
  } catch (const InputError& e) {
    return fmt::format("shard {} of {} is damaged ({})", id.index, id.count, e.what());
  }
  if (record.value("plan", std::string()) != plan.at("id").get<std::string>())
    return fmt::format(
        "shard {} of {} was built from another plan ({}: {})", id.index, id.count, dir.string(),
        record.contains("fingerprint") && record["fingerprint"] != plan.at("fingerprint")
            ? "another input or other options: " + fingerprintDifference(plan.at("fingerprint"), record["fingerprint"])
            : std::string("an earlier prepare"));
  if (record.value("shard", ~0u) != id.index || record.value("of", 0u) != id.count ||
      record.value("charts", std::vector<uint32_t>{}) != shardCharts(plan.at("work").get<std::vector<double>>(), id))
    return fmt::format("shard {} of {} does not hold the charts the plan gives it ({})", id.index, id.count,
                       dir.string());
  for (const json& f : record.value("files", json::array())) {
    const fs::path path = dir / f.value("path", std::string());
    if (!fs::is_regular_file(path, ec) || fs::file_size(path, ec) != f.value("bytes", uint64_t{0}) ||
        fileChecksum(path) != f.value("xxh3", std::string()))
      return fmt::format("shard {} of {} is damaged: {} is not the file the shard wrote", id.index, id.count,
                         path.string());
  }
  return {};
}

// stats.json of a merged build: the figures of a one-process build where they have a meaning
// (the read's from the plan, the charts' from the manifest), and each step's.
json shardStatsJson(const ShardMergeStats& st, const json& plan, const AtlasManifest& m) {
  TerrainBuildStats t;
  t.input = plan.at("fingerprint").at("input").at("path").get<std::string>();
  const json& read = plan.at("read");
  t.read.width = read.at("width").get<uint32_t>();
  t.read.height = read.at("height").get<uint32_t>();
  t.read.spacing = read.at("spacing").get<std::array<double, 2>>();
  t.read.heightRange = read.at("height_range").get<std::array<float, 2>>();
  t.read.voidsFilled = read.at("voids_filled").get<uint64_t>();
  t.read.voidFillMethod = read.at("void_fill_method").get<std::string>();
  t.read.seconds = st.prepare.seconds;
  TerrainWriteStats& w = t.write;
  w.charts.charts = uint32_t(m.charts.size());
  w.charts.samples = uint64_t(m.samplesX) * m.samplesY;
  for (uint32_t k = 0; k <= m.intervalsLog2(); ++k) {
    const uint64_t s = ((m.chartSize - 1) >> k) + 1;
    w.charts.storedSamples += s * s * m.charts.size();
  }
  w.chartsX = m.chartsX;
  w.chartsY = m.chartsY;
  w.chartSize = m.chartSize;
  w.depth = m.depth;
  double slowest = 0.0, cpu = st.prepare.cpuSeconds + st.merge.cpuSeconds;
  uint64_t peak = std::max(st.prepare.peakRssBytes, st.merge.peakRssBytes);
  json shards = json::array();
  for (const ShardBuildStats& s : st.shards) {
    slowest = std::max(slowest, s.step.seconds);
    cpu += s.step.cpuSeconds;
    peak = std::max(peak, s.step.peakRssBytes);
    w.hierarchy.seconds = std::max(w.hierarchy.seconds, s.hierarchySeconds);
    json j = stepJson(s.step);
    j["shard"] = s.id.index;
    j["charts"] = s.charts.size();
    j["bytes"] = s.bytes;
    j["hierarchy_seconds"] = s.hierarchySeconds;
    shards.push_back(std::move(j));
  }
  w.hierarchy.samples = uint64_t(m.charts.size()) * m.chartSize * m.chartSize;
  if (m.imagery.present) {
    const json& planned = plan.at("imagery");
    TerrainImageryStats& im = w.imagery.emplace();
    im.source = m.imagery.source;
    im.scaleLog2 = planned.at("scale").get<uint32_t>();
    im.width = planned.at("width").get<uint32_t>();
    im.height = planned.at("height").get<uint32_t>();
    im.coverage = m.imagery.coverage;
    im.resampling = planned.at("resampling").get<std::string>();
    im.storedSamples = st.imagery.storedSamples;
    im.bytesOnDisk = st.imagery.bytesOnDisk;  // the files the merge finished
    for (const ShardBuildStats& s : st.shards) {
      im.storedSamples += s.imagery.value("stored_samples", uint64_t{0});
      im.writeSeconds = std::max(im.writeSeconds, s.imagery.value("seconds", 0.0));
      im.windows += s.imagery.value("windows", uint64_t{0});
      im.windowSamples = std::max(im.windowSamples, s.imagery.value("window_samples", uint64_t{0}));
    }
  }
  t.bytesOnDisk = st.bytesOnDisk;
  t.totalSeconds = st.prepare.seconds + slowest + st.merge.seconds;
  t.peakRssBytes = peak;
  json j = statsJson(t);
  j["sharded"] = {{"shards", st.shards.size()},  {"prepare", stepJson(st.prepare)},
                  {"merge", stepJson(st.merge)}, {"per_shard", shards},
                  {"balance", st.balance},       {"critical_path_seconds", t.totalSeconds},
                  {"cpu_seconds", cpu}};
  return j;
}

// A chart file into the staged atlas: linked where the file system allows, else copied.
void placeFile(const fs::path& from, const fs::path& to) {
  std::error_code ec;
  fs::create_directories(to.parent_path(), ec);
  fs::create_hard_link(from, to, ec);
  if (ec && !fs::copy_file(from, to, fs::copy_options::overwrite_existing, ec))
    throw InputError(to.string() + ": cannot place the shard's file " + from.string() + " (" + ec.message() + ")");
}

}  // namespace

ShardMergeStats mergeShards(const fs::path& atlas, uint32_t count) {
  const auto t0 = std::chrono::steady_clock::now();
  const double cpu0 = cpuSeconds();
  const fs::path area = shardArea(atlas);
  const json plan = readPlan(area);
  AtlasManifest m = readManifest(area);
  if (count == 0) count = shardCountIn(area);
  std::vector<json> records(count);
  std::vector<std::string> problems;
  for (uint32_t i = 0; i < count; ++i) {
    std::string p = checkShard(area, plan, {i, count}, records[i]);
    if (!p.empty()) problems.push_back(std::move(p));
  }
  if (!problems.empty())
    throw InputError(fmt::format("{}: not merged: {}; run those shards again, then the merge", atlas.string(),
                                 fmt::join(problems, "; ")));
  ShardMergeStats st;
  Hierarchy h;
  h.params = hierarchyParams(m);
  h.charts.resize(m.charts.size());
  for (const ChartInfo& c : m.charts) h.roots.push_back(c.neighbours);
  StagedDirectory stage(atlas, kManifestName, "atlas");
  for (uint32_t i = 0; i < count; ++i) {
    const fs::path dir = area / shardDirName({i, count});
    ShardBuildStats s;
    s.id = {i, count};
    s.charts = records[i]["charts"].get<std::vector<uint32_t>>();
    s.step = stepFromJson(records[i]["step"]);
    s.bytes = records[i].value("bytes", uint64_t{0});
    s.hierarchySeconds = records[i].value("hierarchy_seconds", 0.0);
    s.imagery = records[i].value("imagery", json());
    if (!s.charts.empty()) {
      Hierarchy part = readHierarchy(dir / kShardQuadtrees);
      if (part.charts.size() != s.charts.size())
        throw InputError((dir / kShardQuadtrees).string() + ": not the shard's charts' quadtrees");
      for (size_t k = 0; k < s.charts.size(); ++k) h.charts[s.charts[k]] = std::move(part.charts[k]);
      for (uint32_t c : s.charts) placeFile(dir / m.charts[c].file, stage.path() / m.charts[c].file);
    }
    st.shards.push_back(std::move(s));
  }
  writeHierarchy(stage.path() / m.hierarchyFile, h, m.compression.present);
  if (m.imagery.present) {
    st.imagery = mergeImagery(area, stage.path(), plan, st.shards, m);
    writeManifest(stage.path(), m);
  } else {
    for (const char* name : {kChartListName, kManifestName}) {  // the list first, as writeManifest does
      if (!fs::exists(area / name)) continue;
      const std::vector<uint8_t> bytes = readFileBytes(area / name);
      atomicWriteFile(stage.path() / name, bytes.data(), bytes.size());
    }
  }
  st.prepare = stepFromJson(plan.at("prepare"));
  st.bytesOnDisk = directoryBytes(stage.path());
  double slowest = 0.0, sum = 0.0;
  for (const ShardBuildStats& s : st.shards) slowest = std::max(slowest, s.step.seconds), sum += s.step.seconds;
  st.balance = sum > 0.0 ? slowest / (sum / double(st.shards.size())) : 1.0;
  st.merge = stepStats(t0, cpu0);
  st.stats = shardStatsJson(st, plan, m);
  writeStatsFile(stage.path(), st.stats);
  stage.commit();
  std::error_code ec;
  fs::remove_all(area, ec);
  st.merge = stepStats(t0, cpu0);
  return st;
}

std::string shardSummary(const ShardPrepareStats& s, const fs::path& atlas) {
  return fmt::format("prepared {}: {} charts, plan {}, in {:.2f} s (CPU {:.2f} s, peak {} MiB)\n",
                     shardArea(atlas).string(), s.charts, s.plan, s.step.seconds, s.step.cpuSeconds,
                     s.step.peakRssBytes >> 20);
}

std::string shardSummary(const ShardBuildStats& s, const fs::path& atlas) {
  return fmt::format("shard {} of {} of {}: {} charts, {} bytes, in {:.2f} s (CPU {:.2f} s, peak {} MiB) on {}\n",
                     s.id.index, s.id.count, atlas.string(), s.charts.size(), s.bytes, s.step.seconds,
                     s.step.cpuSeconds, s.step.peakRssBytes >> 20, s.step.host);
}

std::string shardSummary(const ShardMergeStats& s, const fs::path& atlas) {
  std::string out = fmt::format("merged {} shards into {}: {} bytes\n", s.shards.size(), atlas.string(), s.bytesOnDisk);
  out += fmt::format("  prepare  {:9.2f} s  CPU {:9.2f} s  peak {:6} MiB  {}\n", s.prepare.seconds,
                     s.prepare.cpuSeconds, s.prepare.peakRssBytes >> 20, s.prepare.host);
  for (const ShardBuildStats& sh : s.shards)
    out += fmt::format("  shard {:<3}{:9.2f} s  CPU {:9.2f} s  peak {:6} MiB  {}  ({} charts)\n", sh.id.index,
                       sh.step.seconds, sh.step.cpuSeconds, sh.step.peakRssBytes >> 20, sh.step.host, sh.charts.size());
  out += fmt::format("  merge    {:9.2f} s  CPU {:9.2f} s  peak {:6} MiB  {}\n", s.merge.seconds, s.merge.cpuSeconds,
                     s.merge.peakRssBytes >> 20, s.merge.host);
  out += fmt::format(
      "  balance: the slowest shard took {:.2f} times the mean shard's time; critical path {:.2f} s, "
      "CPU {:.2f} s in all\n",
      s.balance, s.stats.at("sharded").at("critical_path_seconds").get<double>(),
      s.stats.at("sharded").at("cpu_seconds").get<double>());
  return out;
}

}  // namespace gimlod
