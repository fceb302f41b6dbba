// Replays the committed inputs of one fuzz target through its LLVMFuzzerTestOneInput, built with the regular
// compiler: the inputs that once crashed it (tests/fuzz/regressions/<target>/), so every crash a fuzzing run found
// stays fixed, and its small hand-written seeds (tests/fuzz/seeds/<target>/).
// A regression that crashes again aborts this binary (the failing file is named on stdout first); under
// `make test-asan` the sanitizers report it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

TEST(FuzzRegressions, Replay) {
  std::vector<std::filesystem::path> files;
  for (const std::filesystem::path dir : {FMV3D_FUZZ_REGRESSIONS, FMV3D_FUZZ_SEEDS})
    if (std::filesystem::is_directory(dir))
      for (const auto& e : std::filesystem::directory_iterator(dir))
        if (e.is_regular_file()) files.push_back(e.path());
  if (files.empty()) GTEST_SKIP() << "no regression inputs or seeds in " << FMV3D_FUZZ_REGRESSIONS;
  std::sort(files.begin(), files.end());
  for (const auto& f : files) {
    std::cout << "replaying " << f.filename().string() << std::endl;
    std::ifstream in(f, std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_EQ(LLVMFuzzerTestOneInput(bytes.data(), bytes.size()), 0) << f;
  }
  std::cout << files.size() << " inputs replayed" << std::endl;
}
