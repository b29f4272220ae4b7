#pragma once
// Helpers shared by the libFuzzer targets: the parsers under test read files, so each input is
// written to a per-process scratch file (on /dev/shm when it exists) first.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

namespace sp::fuzz {

inline std::filesystem::path scratch_file(const std::string& name) {
  const std::filesystem::path dir = std::filesystem::exists("/dev/shm") ? "/dev/shm" : "/tmp";
  return dir / ("sp_fuzz_" + std::to_string(::getpid()) + "_" + name);
}

inline void write_file(const std::filesystem::path& file, const void* data, std::size_t size) {
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
}

}  // namespace sp::fuzz
