// `gimlod build`: its options (the ones the input's kind takes are told apart when it runs) and
// the build they ask for, in one process or across processes (apps/shard_command.h).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>

#include "apps/shard_command.h"
#include "pipeline/build_options.h"

namespace gimlod {

// What the command line gives: the options shared by both kinds of input in `common`, the others
// in the struct of the kind they apply to, and the ones parsed into library values when the build
// runs as text or in command-line units.
struct BuildArgs {
  CLI::App* command = nullptr;
  CLI::Option* chartSizeOption = nullptr;  // --chart-size, parsed into terrain.chartSize
  CommonBuildOptions common;
  TerrainBuildOptions terrain;
  MeshBuildOptions mesh;
  std::string chartsArg = "auto", quadsArg = "auto", normalsArg = "auto", sizingArg = "patch";
  std::string quadMapArg = "bilinear", chartMetricArg = "auto", fidelityArg = "fast";
  std::string maxMemory = "4G";
  std::string ellipsoid;
  bool noFidelity = false, uncompressed = false;
  double sampleErrorPercent = -1.0;  // < 0 and not given: the density's default
  double positionTolerancePercent = 100.0 * kDefaultPositionTolerance;
  uint32_t imageryScale = 0;
  std::vector<double> spacingArg, imageryExtent;
  ShardArgs shardArgs;
};

// Adds the `build` subcommand, its options parsed into `a` (which must outlive the parse).
CLI::App* addBuildCommand(CLI::App& app, BuildArgs& a);

// Runs the build `a` asks for, printing its summary; argv is the command line (--emit-slurm writes
// it into its scripts). Returns the exit status; throws InputError for a bad option or input.
int runBuildCommand(const BuildArgs& a, int argc, char** argv);

// The command-line flag that sets the library parameter `name` (InputError::message); the name
// itself for one the command line does not set.
std::string flagFor(std::string_view name);

}  // namespace gimlod
