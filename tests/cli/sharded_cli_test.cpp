// `gimlod build` across processes, as a user runs it: three MPI ranks under mpirun, the Slurm
// scripts --emit-slurm writes (run here as Slurm would run them, one job after another and the
// array's tasks with their ids), each giving the one-process atlas byte for byte; and the
// refusals of what cannot be sharded.
#include <gtest/gtest.h>

#include <unistd.h>

#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

std::string tileBuild(const fs::path& atlas) {
  return test::appPath().string() + " build " + test::quoted(test::repoData() / "terrain/mt_rainier_90m.tif") + " -o " +
         test::quoted(atlas) + " --chart-size 129";
}

TEST(ShardedCli, ThreeMpiRanksGiveTheOneProcessAtlas) {
  test::TempDir dir("gimlod-sharded-mpi");
  std::string out;
  ASSERT_EQ(test::runCommand(tileBuild(dir.path() / "one.atlas"), &out), 0) << out;
  // CI runs as root, which mpirun refuses unless told.
  const std::string mpirun =
      std::string("mpirun --oversubscribe ") + (::geteuid() == 0 ? "--allow-run-as-root " : "") + "-n 3 ";
  ASSERT_EQ(test::runCommand(mpirun + tileBuild(dir.path() / "mpi.atlas") + " --mpi --threads 1", &out), 0) << out;
  for (const char* rank : {"[rank 0]", "[rank 1]", "[rank 2]"}) EXPECT_NE(out.find(rank), std::string::npos) << out;
  EXPECT_NE(out.find("merged 12 shards"), std::string::npos) << out;  // four a rank
  test::expectSameFiles(dir.path() / "one.atlas", dir.path() / "mpi.atlas", "stats.json");
  EXPECT_NE(test::fileBytes(dir.path() / "mpi.atlas/stats.json").find("\"balance\""), std::string::npos);
  // As many shards as asked.
  ASSERT_EQ(test::runCommand(mpirun + tileBuild(dir.path() / "mpi5.atlas") + " --mpi --shards 5 --threads 1", &out), 0)
      << out;
  EXPECT_NE(out.find("merged 5 shards"), std::string::npos) << out;
  test::expectSameFiles(dir.path() / "one.atlas", dir.path() / "mpi5.atlas", "stats.json");
}

// The shipped tile draped with its imagery; the scripts are emitted from the data's folder, with
// the input and the imagery named relative to it, and run from elsewhere.
TEST(ShardedCli, TheSlurmScriptsRunInTurnGiveTheOneProcessAtlas) {
  test::TempDir dir("gimlod-sharded-slurm");
  std::string out;
  const std::string drape = " --imagery-scale 1 --imagery";
  ASSERT_EQ(test::runCommand(tileBuild(dir.path() / "one.atlas") + drape + " " +
                                 test::quoted(test::repoData() / "terrain/mt_rainier_imagery.tif"),
                             &out),
            0)
      << out;
  const fs::path jobs = dir.path() / "jobs";
  ASSERT_EQ(test::runCommand("cd " + test::quoted(test::repoData() / "terrain") + " && " + test::appPath().string() +
                                 " build mt_rainier_90m.tif -o " + test::quoted(dir.path() / "slurm.atlas") +
                                 " --chart-size 129" + drape + "=mt_rainier_imagery.tif --threads 1 --emit-slurm " +
                                 test::quoted(jobs) + " --shards 3",
                             &out),
            0)
      << out;
  EXPECT_FALSE(fs::exists(dir.path() / "slurm.atlas")) << "--emit-slurm built";
  const std::string submit = test::fileBytes(jobs / "submit.sh");
  EXPECT_NE(submit.find("--dependency=afterok:\"$prepare\" shards.sbatch"), std::string::npos) << submit;
  EXPECT_NE(submit.find("--dependency=afterok:\"$shards\" merge.sbatch"), std::string::npos) << submit;
  EXPECT_NE(test::fileBytes(jobs / "shards.sbatch").find("#SBATCH --array=0-2"), std::string::npos);
  EXPECT_NE(test::fileBytes(jobs / "shards.sbatch").find("#SBATCH --cpus-per-task=1"), std::string::npos);
  // As Slurm runs them: the prepare, the array's tasks (in any order), the merge.
  ASSERT_EQ(test::runCommand("bash " + test::quoted(jobs / "prepare.sbatch"), &out), 0) << out;
  for (const char* task : {"2", "0", "1"})
    ASSERT_EQ(test::runCommand(
                  std::string("SLURM_ARRAY_TASK_ID=") + task + " bash " + test::quoted(jobs / "shards.sbatch"), &out),
              0)
        << out;
  ASSERT_EQ(test::runCommand("bash " + test::quoted(jobs / "merge.sbatch"), &out), 0) << out;
  test::expectSameFiles(dir.path() / "one.atlas", dir.path() / "slurm.atlas", "stats.json");
}

// A one-node Slurm cluster started here (scripts/slurm/local_cluster.sh: slurmctld and slurmd on
// ports of their own, munge): submit.sh submits the prepare, the array and the merge, which Slurm
// runs in their order.
TEST(ShardedCli, AOneNodeSlurmClusterRunsTheSubmittedBuild) {
  test::TempDir dir("gimlod-sharded-cluster");
  std::string out;
  ASSERT_EQ(test::runCommand(tileBuild(dir.path() / "one.atlas"), &out), 0) << out;
  const fs::path script = test::repoData().parent_path() / "scripts/slurm/local_cluster.sh";
  const fs::path cluster = dir.path() / "cluster";
  ASSERT_EQ(test::runCommand("bash " + test::quoted(script) + " start " + test::quoted(cluster), &out), 0) << out;
  struct Stop {
    std::string command;
    ~Stop() { test::runCommand(command); }
  } stop{"bash " + test::quoted(script) + " stop " + test::quoted(cluster)};
  const std::string conf = "SLURM_CONF=" + test::quoted(cluster / "slurm.conf") + " ";
  const fs::path jobs = dir.path() / "jobs", atlas = dir.path() / "slurm.atlas";
  ASSERT_EQ(
      test::runCommand(tileBuild(atlas) + " --threads 1 --emit-slurm " + test::quoted(jobs) + " --shards 3", &out), 0)
      << out;
  ASSERT_EQ(test::runCommand(conf + "bash " + test::quoted(jobs / "submit.sh"), &out), 0) << out;
  EXPECT_NE(out.find("(array 0-2)"), std::string::npos) << out;
  bool done = false;
  for (int i = 0; i < 600 && !done; ++i) {
    std::string queue;
    test::runCommand(conf + "squeue -h", &queue);
    done = queue.find_first_not_of(" \n") == std::string::npos;
    if (!done) ::usleep(200000);
  }
  ASSERT_TRUE(done) << "the jobs did not finish in 120 s";
  std::string logs;
  for (const std::string& f : test::filesUnder(jobs / "logs")) logs += test::fileBytes(jobs / "logs" / f);
  EXPECT_NE(logs.find("merged 3 shards"), std::string::npos) << logs;
  EXPECT_NE(logs.find("shard 2 of 3"), std::string::npos) << logs;
  ASSERT_TRUE(fs::exists(atlas)) << logs;
  test::expectSameFiles(dir.path() / "one.atlas", atlas, "stats.json");
}

TEST(ShardedCli, BadShardOptionsAreRefusedByName) {
  test::TempDir dir("gimlod-sharded-bad");
  const std::string app = test::appPath().string();
  const fs::path atlas = dir.path() / "a.atlas";
  struct Case {
    std::string command, expected;
  };
  const std::vector<Case> cases = {
      {tileBuild(atlas) + " --shard 3/3", "--shard \"3/3\" must be I/N"},
      {tileBuild(atlas) + " --shard 0/2", "plan.json: no plan"},
      {app + " merge " + test::quoted(atlas), "plan.json: no plan"},
      {app + " build " + test::quoted(test::repoData() / "meshes/bun_zipper.ply") + " -o " + test::quoted(atlas) +
           " --prepare",
       "a mesh is built in one process"},
      {tileBuild(atlas) + " --prepare --shard 0/2", "excludes"},
  };
  for (const Case& c : cases) {
    std::string out;
    EXPECT_NE(test::runCommand(c.command, &out), 0) << c.command;
    EXPECT_NE(out.find(c.expected), std::string::npos) << c.command << "\n" << out;
  }
  EXPECT_FALSE(fs::exists(atlas));
}

}  // namespace
}  // namespace gimlod
