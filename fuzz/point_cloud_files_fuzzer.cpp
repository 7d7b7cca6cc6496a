// Fuzz target: point-cloud files (cloud/cloud_io.hpp: PCD ascii/binary/binary_compressed, PLY
// ascii/binary, KITTI .bin) and CARMEN laser logs (io/carmen_import.hpp), read from files as the
// commands read them. The first byte picks the format (the file's extension); the rest is the
// file. Any input must be read or refused with an error, never crash.

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/io/carmen_import.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion;
  if (size == 0) return 0;
  static const char* kExtensions[] = {".pcd", ".ply", ".bin", ".log"};
  const char* extension = kExtensions[data[0] % 4];
  const std::string path =
      (std::filesystem::temp_directory_path() / ("hanzo_fuzz_cloud_" + std::to_string(::getpid()) + extension)).string();
  {
    std::ofstream file(path, std::ios::binary | std::ios::trunc);
    file.write(reinterpret_cast<const char*>(data) + 1, static_cast<std::streamsize>(size - 1));
  }
  if (data[0] % 4 == 3) {
    (void)io::read_carmen(path, {});
  } else {
    (void)cloud::read_cloud(path);
  }
  std::filesystem::remove(path);
  return 0;
}
