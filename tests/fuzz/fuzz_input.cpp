#include "tests/fuzz/fuzz_input.h"

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <stdexcept>

namespace gimlod::fuzz {

namespace {

struct Scratch {
  std::filesystem::path dir;
  Scratch() {
    const std::filesystem::path base =
        std::filesystem::exists("/dev/shm") ? "/dev/shm" : std::filesystem::temp_directory_path();
    dir = base / ("gimlod-fuzz-" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
  }
  ~Scratch() {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
};

}  // namespace

const std::filesystem::path& scratchDirectory() {
  static Scratch scratch;
  return scratch.dir;
}

std::filesystem::path writeInput(const std::string& name, const uint8_t* data, size_t size) {
  const std::filesystem::path path = scratchDirectory() / name;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) throw std::runtime_error("cannot write fuzz input " + path.string());
  if (size > 0 && std::fwrite(data, 1, size, f) != size) {
    std::fclose(f);
    throw std::runtime_error("cannot write fuzz input " + path.string());
  }
  std::fclose(f);
  return path;
}

}  // namespace gimlod::fuzz
