// Helpers for the libFuzzer harnesses: every reader under test takes a path, so each input is
// written to one file in a private directory (tmpfs when available) and read back from there.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

namespace gimlod::fuzz {

// A directory private to this process, created on first use (under /dev/shm when it exists).
const std::filesystem::path& scratchDirectory();

// Writes data to scratchDirectory()/name, replacing what was there; returns the path.
std::filesystem::path writeInput(const std::string& name, const uint8_t* data, size_t size);

}  // namespace gimlod::fuzz
