#include "apps/shard_command.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <thread>
#include <fstream>
#include <iostream>
#include <vector>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include "core/atlas_format.h"
#include "pipeline/sharded_build.h"

#ifdef GIMLOD_WITH_MPI
#include <mpi.h>
#endif

namespace fs = std::filesystem;

namespace gimlod {
namespace {

// A word for a POSIX shell, quoted where it needs it.
std::string shellQuoted(const std::string& s) {
  if (!s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-+=/.,:@%") ==
                        std::string::npos)
    return s;
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// The build's command line for a Slurm job: this gimlod by its absolute path, every argument but
// --emit-slurm and --shards (and their values), paths made absolute (the jobs start elsewhere).
std::string jobCommand(const TerrainBuildOptions& o, int argc, char** argv) {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  std::vector<std::string> words{ec ? std::string(argv[0]) : self.string(), "build", fs::absolute(o.input).string(),
                                 "-o", fs::absolute(o.output).string()};
  bool afterBuild = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (!afterBuild) {
      afterBuild = a == "build";
      continue;
    }
    auto valueOf = [&](const std::string& flag) { return a == flag || a.rfind(flag + "=", 0) == 0; };
    if (valueOf("--emit-slurm") || valueOf("--shards") || valueOf("-o") || valueOf("--output")) {
      if (a.find('=') == std::string::npos) ++i;
      continue;
    }
    if (fs::path(a) == o.input && a.rfind("-", 0) != 0) continue;  // the input, written above
    const bool isPathOption = valueOf("--imagery");
    const size_t equals = a.find('=');
    if (isPathOption && equals != std::string::npos) {  // --imagery=PATH
      words.push_back(a.substr(0, equals + 1) + fs::absolute(a.substr(equals + 1)).string());
      continue;
    }
    words.push_back(a);
    if (isPathOption && i + 1 < argc) words.push_back(fs::absolute(argv[++i]).string());
  }
  std::string out;
  for (const std::string& w : words) {
    if (!out.empty()) out += ' ';
    out += shellQuoted(w);
  }
  return out;
}

void writeScript(const fs::path& path, const std::string& text) {
  atomicWriteFile(path, text.data(), text.size());
  ::chmod(path.c_str(), 0755);
}

// Slurm batch scripts for the build: prepare.sbatch, shards.sbatch (a job array), merge.sbatch and
// submit.sh, which submits them chained by --dependency=afterok.
int emitSlurm(const TerrainBuildOptions& o, const ShardArgs& a, int argc, char** argv) {
  const uint32_t n = a.shards ? a.shards : 8;
  if (n > kMaxShards) throw InputError(fmt::format("{} {} must be at most {}", optionRef("shards"), n, kMaxShards));
  const fs::path dir = fs::absolute(a.slurmDir);
  std::error_code ec;
  fs::create_directories(dir / "logs", ec);
  if (ec) throw InputError(dir.string() + ": cannot create it (" + ec.message() + ")");
  const std::string cmd = jobCommand(o, argc, argv);
  const std::string atlas = shellQuoted(fs::absolute(o.output).string());
  const std::string cpus = o.threads ? fmt::format("#SBATCH --cpus-per-task={}\n", o.threads) : std::string();
  auto header = [&](const std::string& name, const std::string& extra) {
    return fmt::format(
        "#!/bin/bash\n#SBATCH --job-name=gimlod-{}\n#SBATCH --output={}/logs/%x-%A_%a.out\n{}"
        "# Written by gimlod build --emit-slurm; every node must see the input and {}.shards.\n"
        "set -euo pipefail\n",
        name, dir.string(), extra, fs::absolute(o.output).string());
  };
  writeScript(dir / "prepare.sbatch", header("prepare", "#SBATCH --ntasks=1\n" + cpus) + cmd + " --prepare\n");
  writeScript(dir / "shards.sbatch",
              header("shard", fmt::format("#SBATCH --ntasks=1\n{}#SBATCH --array=0-{}\n", cpus, n - 1)) + cmd +
                  fmt::format(" --shard \"${{SLURM_ARRAY_TASK_ID}}/{}\"\n", n));
  const fs::path self = fs::path(cmd.substr(0, cmd.find(' ')));
  writeScript(dir / "merge.sbatch", header("merge", "#SBATCH --ntasks=1\n") + self.string() + " merge " + atlas +
                                        fmt::format(" --shards {}\n", n));
  writeScript(
      dir / "submit.sh",
      fmt::format("#!/bin/bash\n# Submits the build's three steps, each after the last succeeds.\nset -euo pipefail\n"
                  "cd {}\nprepare=$(sbatch --parsable prepare.sbatch)\n"
                  "shards=$(sbatch --parsable --dependency=afterok:\"$prepare\" shards.sbatch)\n"
                  "merge=$(sbatch --parsable --dependency=afterok:\"$shards\" merge.sbatch)\n"
                  "echo \"prepare $prepare, shards $shards (array 0-{}), merge $merge\"\n",
                  shellQuoted(dir.string()), n - 1));
  std::cout << fmt::format(
      "wrote {}/submit.sh (prepare.sbatch, shards.sbatch with {} array tasks, merge.sbatch); run "
      "it on the cluster's login node\n",
      dir.string(), n);
  return 0;
}

#ifdef GIMLOD_WITH_MPI

std::string spelled(const TerrainBuildOptions& o, const InputError& e) {
  return o.spellOption ? e.message(o.spellOption) : std::string(e.what());
}

// Waits for a request without spinning: MPI's own waits poll the network at full speed, which on
// ranks sharing a machine takes the cores the working ranks need (a prepare, a last shard).
void waitIdly(MPI_Request& request) {
  for (int done = 0;;) {
    MPI_Test(&request, &done, MPI_STATUS_IGNORE);
    if (done) return;
    ::usleep(20000);
  }
}

// Runs a step (the prepare, a shard, the merge); its exit status (2: bad input or options, 1:
// another failure), a failure logged under the step's name.
template <typename Step>
int runLogged(const TerrainBuildOptions& o, const std::string& what, Step&& step) {
  try {
    step();
    return 0;
  } catch (const InputError& e) {
    spdlog::error("{}: {}", what, spelled(o, e));
    return 2;
  } catch (const std::exception& e) {
    spdlog::error("{}: {}", what, e.what());
    return 1;
  }
}

// Builds shard `next` of `shards`, logging a failure; returns whether it was built.
bool runShard(const TerrainBuildOptions& o, uint32_t next, uint32_t shards) {
  return runLogged(o, fmt::format("shard {} of {}", next, shards), [&] {
           std::cout << shardSummary(buildShard(o, {next, shards}), o.output) << std::flush;
         }) == 0;
}

constexpr int kTagAsk = 1, kTagGive = 2;
constexpr uint32_t kShardsPerRank = 4;

// The work list: rank 0 holds the next shard's number; its dispatcher thread answers every other
// rank that asks (a message each way), while its main thread takes shards from the same counter,
// so a fast rank takes more. Returns whether every shard this rank took was built.
// Where MPI allows calls from one thread at a time only (below MPI_THREAD_SERIALIZED), rank 0 only
// dispatches.
bool takeShards(const TerrainBuildOptions& o, uint32_t shards, int rank, int size, bool rank0Works) {
  bool ok = true;
  if (rank != 0) {
    for (;;) {
      int next = 0;
      MPI_Send(&next, 1, MPI_INT, 0, kTagAsk, MPI_COMM_WORLD);
      MPI_Request reply;
      MPI_Irecv(&next, 1, MPI_INT, 0, kTagGive, MPI_COMM_WORLD, &reply);
      waitIdly(reply);
      if (next >= int(shards)) return ok;
      ok = runShard(o, uint32_t(next), shards) && ok;
    }
  }
  std::atomic<int> counter{0};
  auto dispatch = [&] {
    for (int open = size - 1; open > 0;) {
      int ignored = 0;
      MPI_Status status;
      MPI_Request ask;
      MPI_Irecv(&ignored, 1, MPI_INT, MPI_ANY_SOURCE, kTagAsk, MPI_COMM_WORLD, &ask);
      for (int done = 0; !done;) {
        MPI_Test(&ask, &done, &status);
        if (!done) ::usleep(5000);
      }
      const int next = counter++;
      MPI_Send(&next, 1, MPI_INT, status.MPI_SOURCE, kTagGive, MPI_COMM_WORLD);
      if (next >= int(shards)) --open;
    }
  };
  if (!rank0Works) {
    dispatch();
    return ok;
  }
  std::thread dispatcher(dispatch);
  for (int next; (next = counter++) < int(shards);) ok = runShard(o, uint32_t(next), shards) && ok;
  dispatcher.join();
  return ok;
}

// Rank 0's value, on every rank.
int fromRank0(int status) {
  MPI_Request request;
  MPI_Ibcast(&status, 1, MPI_INT, 0, MPI_COMM_WORLD, &request);
  waitIdly(request);
  return status;
}

int runMpi(const TerrainBuildOptions& o, const ShardArgs& a) {
  int provided = 0;
  // Rank 0's dispatcher thread calls MPI while its main thread builds shards (which makes no MPI call).
  MPI_Init_thread(nullptr, nullptr, MPI_THREAD_SERIALIZED, &provided);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  spdlog::set_pattern(fmt::format("[%H:%M:%S.%e] [rank {}] [%l] %v", rank));
  // Unless told, kShardsPerRank shards a rank (at most one a chart), so that the work list evens
  // out what the plan's estimate of each chart's work misses.
  uint32_t shards = a.shards;
  int status = 0;
  if (rank == 0) {
    status = runLogged(o, "prepare", [&] {
      const ShardPrepareStats prepared = prepareShards(o);
      std::cout << shardSummary(prepared, o.output) << std::flush;
      if (!shards) shards = std::clamp<uint32_t>(prepared.charts, 1, kShardsPerRank * uint32_t(size));
      spdlog::info("{} ranks, {} shards", size, shards);
    });
  }
  if (fromRank0(status) == 0) {
    shards = uint32_t(fromRank0(int(shards)));
    const bool rank0Works = size == 1 || provided >= MPI_THREAD_SERIALIZED;
    const int mine = takeShards(o, shards, rank, size, rank0Works) ? 0 : 1;
    int failed = 0;
    MPI_Request request;
    MPI_Iallreduce(&mine, &failed, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD, &request);
    waitIdly(request);
    if (rank == 0 && failed) {
      spdlog::error(
          "some shards failed (above); their shard area is kept: run them with --shard I/{}, then gimlod "
          "merge",
          shards);
      status = 1;
    } else if (rank == 0) {
      status = runLogged(o, "merge",
                         [&] { std::cout << shardSummary(mergeShards(o.output, shards), o.output) << std::flush; });
    }
    status = fromRank0(status);
  }
  MPI_Finalize();
  return status;
}

#endif

}  // namespace

int runShardedBuild(const TerrainBuildOptions& o, const ShardArgs& a, int argc, char** argv) {
  if (!a.slurmDir.empty()) return emitSlurm(o, a, argc, argv);
  if (a.mpi) {
#ifdef GIMLOD_WITH_MPI
    return runMpi(o, a);
#else
    throw InputError(
        "--mpi: this gimlod was built without MPI (install libopenmpi-dev, then configure and build "
        "again)");
#endif
  }
  if (a.prepare) {
    std::cout << shardSummary(prepareShards(o), o.output);
    return 0;
  }
  std::cout << shardSummary(buildShard(o, parseShardId(a.shard)), o.output);
  return 0;
}

}  // namespace gimlod
