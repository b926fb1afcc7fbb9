// A build split across processes or machines: a prepare step, shards, and a merge, each its own
// command, so that any batch scheduler (Slurm job arrays, Kubernetes indexed jobs) or MPI can run
// them (apps/mpi_build.h, docs/distributed.md). Every step works in the shard area beside the
// atlas (ATLAS.shards), which every machine sees on a shared file system.
// - prepare: what must see the whole input, once: the DEM read into a compressed scratch raster,
//   its voids filled (the fill's coarse levels span the DEM), the height range and step chosen.
//   It writes the manifest the atlas will have and a plan (plan.json): the options and the
//   input's identity, and each chart's estimated work. A new prepare replaces the area.
// - shard I/N (I from 0): the chart files of its charts and their quadtrees, into
//   ATLAS.shards/shard-I-of-N, staged and renamed into place when done, with a record
//   (shard.json) of its charts, each file's size and XXH3 checksum, its times and peak memory.
//   The split is fixed by the plan and N: contiguous runs of charts (in the manifest's order, so
//   the windows a shard reads overlap least) whose largest estimated work is the least it can be.
//   A shard that fails or is killed leaves nothing behind, and can be run again alone.
// - merge: checks that every shard of the N is there, from this plan, with these options, and
//   intact (any other is named, and nothing is written); then writes the hierarchy file from the
//   shards' quadtrees, the manifest and stats.json (each shard's time, CPU time and peak memory,
//   and the load balance), links the chart files into a staged atlas and renames it into place;
//   the shard area is removed.
// The atlas is byte-identical to a one-process build of the same input and options, whatever N
// is, every file but stats.json. DEMs only, without imagery, for now.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "atlas/terrain/imagery.h"
#include "pipeline/build_options.h"

namespace gimlod {

// Shard `index` of `count`, index from 0 (as Slurm's array task ids and MPI's ranks count).
struct ShardId {
  uint32_t index = 0, count = 1;
};
// Parses "I/N" with 0 <= I < N <= kMaxShards. Throws InputError naming the option.
inline constexpr uint32_t kMaxShards = 65536;
ShardId parseShardId(std::string_view text);

// The shard area of an atlas: ATLAS.shards beside it.
std::filesystem::path shardArea(const std::filesystem::path& atlas);

// The charts of shard `id` given each chart's estimated work: the id.index-th of id.count
// contiguous runs that minimise the largest run's work (a run may be empty when there are fewer
// charts than shards). Deterministic.
std::vector<uint32_t> shardCharts(const std::vector<double>& work, ShardId id);

// What a step measured, for its log line and the merge's report.
struct ShardStepStats {
  double seconds = 0.0;     // wall
  double cpuSeconds = 0.0;  // user + system, all threads
  uint64_t peakRssBytes = 0;
  std::string host;
};

struct ShardPrepareStats {
  ShardStepStats step;
  uint32_t charts = 0;
  std::string plan;  // the plan's id
};
// The prepare step of options.output's build. Throws InputError naming the file or the option
// (a mesh, imagery: not yet sharded).
ShardPrepareStats prepareShards(const TerrainBuildOptions& options);

struct ShardBuildStats {
  ShardId id;
  std::vector<uint32_t> charts;
  ShardStepStats step;
  uint64_t bytes = 0;  // the shard's chart and quadtree files
  double hierarchySeconds = 0.0;
  nlohmann::json imagery;  // its imagery's figures (null without imagery)
};
// Shard `id` of options.output's build. Throws InputError when the area has no plan, or one made
// from another input or other options than these.
ShardBuildStats buildShard(const TerrainBuildOptions& options, ShardId id);

struct ShardMergeStats {
  std::vector<ShardBuildStats> shards;
  ShardStepStats prepare, merge;
  uint64_t bytesOnDisk = 0;
  double balance = 0.0;       // the slowest shard's time over the mean shard's
  ImageryWriteStats imagery;  // the imagery's levels the merge wrote, and its files' bytes
  nlohmann::json stats;       // what stats.json holds
};
// Merges the shards of the build of `atlas` (count: the N the shards were run with; 0: the one N
// the area holds). Throws InputError naming every shard that is missing, damaged or from another
// plan, before anything is written.
ShardMergeStats mergeShards(const std::filesystem::path& atlas, uint32_t count = 0);

// The summary printed after a step.
std::string shardSummary(const ShardPrepareStats& s, const std::filesystem::path& atlas);
std::string shardSummary(const ShardBuildStats& s, const std::filesystem::path& atlas);
std::string shardSummary(const ShardMergeStats& s, const std::filesystem::path& atlas);

}  // namespace gimlod
