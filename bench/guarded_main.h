// A benchmark's main around its body: whatever the body throws (bad input, a missing file) is
// named on stderr with the program's name, and the exit status is 1, instead of a terminate.
#pragma once

#include <cstdio>
#include <exception>

template <typename Run>
int guardedMain(int argc, char** argv, Run run) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", argv[0], e.what());
    return 1;
  }
}
