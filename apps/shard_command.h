// `gimlod build` across processes: --prepare, --shard I/N (pipeline/sharded_build.h), --mpi (the
// three steps in one mpirun, when the app is built with OpenMPI) and --emit-slurm DIR (the three
// steps as Slurm batch jobs chained by their dependencies).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "pipeline/build_options.h"

namespace gimlod {

struct ShardArgs {
  bool prepare = false;
  std::string shard;  // "I/N"
  bool mpi = false;
  uint32_t shards = 0;  // --mpi: 0 is the ranks; --emit-slurm: 0 is 8
  std::filesystem::path slurmDir;
  bool any() const { return prepare || !shard.empty() || mpi || !slurmDir.empty(); }
};

// Runs the step the arguments ask for; argv is the command line, which --emit-slurm writes into
// its scripts with its own options replaced. Returns the exit status; throws InputError.
int runShardedBuild(const TerrainBuildOptions& options, const ShardArgs& args, int argc, char** argv);

}  // namespace gimlod
