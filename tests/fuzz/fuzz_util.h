#pragma once
// Shared by the fuzz targets: the bytes as a file (the readers take paths).
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>

inline std::filesystem::path bytes_to_file(const uint8_t* data, size_t size,
                                           const char* extension) {
  static const std::filesystem::path file =
      std::filesystem::temp_directory_path() /
      ("organfit_fuzz_" + std::to_string(getpid()) + extension);
  FILE* f = std::fopen(file.c_str(), "wb");
  if (f) {
    std::fwrite(data, 1, size, f);
    std::fclose(f);
  }
  return file;
}
