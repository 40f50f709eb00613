// Replays the fuzzing corpora (tests/fuzz/corpus, seeds plus what the libFuzzer campaigns kept) through
// the harness bodies in the normal build, so every input that once mattered to a fuzzer, including the
// crashes they found, runs in CI under gcc. An escaping exception or a broken invariant fails the case.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "fuzz/fuzz_targets.h"

namespace fluorosim {
namespace {

namespace fs = std::filesystem;

const fs::path kCorpus = fs::path(FLUOROSIM_SOURCE_DIR) / "tests" / "fuzz" / "corpus";

void replay(const std::string& harness, int (*body)(const uint8_t*, size_t)) {
    const fs::path dir = kCorpus / harness;
    ASSERT_TRUE(fs::is_directory(dir)) << dir;
    size_t files = 0;
    for (const auto& e : fs::directory_iterator(dir)) {
        if (!e.is_regular_file()) continue;
        std::ifstream in(e.path(), std::ios::binary);
        const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        SCOPED_TRACE(e.path().string());
        EXPECT_NO_THROW(EXPECT_EQ(body(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()), 0));
        ++files;
    }
    EXPECT_GT(files, 0u) << "empty corpus " << dir;
}

TEST(FuzzCorpus, SceneLoader) { replay("scene_loader", fuzz::sceneLoader); }
TEST(FuzzCorpus, SwcReader) { replay("swc_reader", fuzz::swcReader); }
TEST(FuzzCorpus, SpectraCsv) { replay("spectra_csv", fuzz::spectraCsv); }
TEST(FuzzCorpus, Units) { replay("units", fuzz::units); }

}  // namespace
}  // namespace fluorosim
