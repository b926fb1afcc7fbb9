// `gimlod bench`: adaptation benchmark over a camera path for the multi-grained adapters and the
// baselines, in error-threshold mode (node budgets) or triangle-budget mode (node x triangle
// budgets), with per-frame and summary CSVs and a frame-time cost model.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 and figure 6.
#pragma once

#include <cstdint>
#include <string>

#include <CLI/CLI.hpp>

#include "apps/view_args.h"

namespace gimlod {

struct BenchArgs {
  std::string atlas, output;
  CameraArgs camera;
  std::string mode = "error";
  std::string nodes = "100,250,500,1000,2000";
  std::string triangles = "100000,200000,400000,800000";
  std::string size = "1280x720";
  std::string algorithms = "ours,fixed,greedy";
  uint32_t repeat = 1;
  uint32_t maxRounds = 16;  // quad queue: split/merge rounds per frame (work cap; state persists)
  double tolerance = 1.0;
  double frameMs = 0.0, triRate = 0.0;
  // The frame-time controller on the cost model (with --frame-ms and --tri-rate in budget mode):
  // frames it runs (cycling the path), and the factor the triangle rate is multiplied by halfway
  // (a jump in load).
  uint32_t controlFrames = 240;
  double loadStep = 0.5;
  bool render = false;
  std::string gpuCache = "auto";  // --render: the GPU page pool in bytes (StreamingArgs::gpuCache)
  // Set by the parser: which options were given explicitly.
  bool toleranceGiven = false, trianglesGiven = false;
};

// Registers the `bench` subcommand on app, parsing into args (which must outlive app's parse).
CLI::App* addBenchCommand(CLI::App& app, BenchArgs& args);

// Runs the benchmark; writes OUT/bench.csv, OUT/summary.csv and OUT/cost_model.json and prints a
// summary. Throws InputError on invalid options or inputs. Returns the process exit code.
int runBench(const BenchArgs& args);

}  // namespace gimlod
