// The memory cap: sizes parse and print, estimates beyond the cap are refused naming the input, and
// the cap can be set and restored.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "render/film.h"

namespace fluorosim {
namespace {

// Restores the default cap when a test ends.
struct CapGuard {
    explicit CapGuard(uint64_t bytes) { setMemoryCapBytes(bytes); }
    ~CapGuard() { setMemoryCapBytes(0); }
};

TEST(MemoryCap, ParsesSizes) {
    EXPECT_EQ(parseByteSize("8GiB"), uint64_t(8) << 30);
    EXPECT_EQ(parseByteSize("512 MiB"), uint64_t(512) << 20);
    EXPECT_EQ(parseByteSize("2G"), uint64_t(2) << 30);
    EXPECT_EQ(parseByteSize("1e9"), uint64_t(1000000000));
    EXPECT_EQ(parseByteSize("100KB"), uint64_t(100000));
    EXPECT_EQ(parseByteSize("1.5 KiB"), uint64_t(1536));
    for (const char* bad : {"", "lots", "-1GiB", "0", "nan", "inf", "8 parsec", "1e30GiB", "GiB"}) EXPECT_FALSE(parseByteSize(bad)) << bad;
}

TEST(MemoryCap, FormatsSizes) {
    EXPECT_EQ(formatBytes(512), "512 B");
    EXPECT_EQ(formatBytes(8.0 * (uint64_t(1) << 30)), "8 GiB");
    EXPECT_EQ(formatBytes(1.5 * 1024 * 1024), "1.5 MiB");
    EXPECT_EQ(formatBytes(INFINITY), "more than 10^308 bytes");
}

TEST(MemoryCap, DefaultIsAtMostEightGiB) {
    setMemoryCapBytes(0);
    EXPECT_EQ(memoryCapBytes(), defaultMemoryCapBytes());
    EXPECT_LE(defaultMemoryCapBytes(), uint64_t(8) << 30);
    EXPECT_GT(defaultMemoryCapBytes(), uint64_t(0));
}

TEST(MemoryCap, EstimatesBeyondTheCapAreRefusedNamingTheInput) {
    const CapGuard cap(uint64_t(1) << 30);
    EXPECT_NO_THROW(requireMemory(1e9, "small"));
    try {
        requireMemory(3e12, "scene.json: /camera/resolution");
        ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("scene.json: /camera/resolution"), std::string::npos) << m;
        EXPECT_NE(m.find("2.7 TiB"), std::string::npos) << m;
        EXPECT_NE(m.find("memory cap of 1 GiB"), std::string::npos) << m;
    }
    EXPECT_THROW(requireMemory(NAN, "nan"), ConfigError);
    EXPECT_THROW(requireMemory(INFINITY, "inf"), ConfigError);
}

TEST(MemoryCap, FilmsBeyondTheCapAreRefusedBeforeAllocating) {
    const CapGuard cap(uint64_t(64) << 20);
    const TabulatedSpectrum one({360, 830}, {1, 1});
    // 8192 x 8192 pixels with 4000 bins would take terabytes: 28 bytes per pixel and channel (two double
    // sums, three float layers) and per pixel 4 (non-finite counts) and one staged sample of a pass.
    EXPECT_DOUBLE_EQ(Film::estimatedBytes(8192, 8192, 4000), 8192.0 * 8192.0 * (4003.0 * 28 + 4 + sizeof(Film::Row::Sample)));
    EXPECT_GT(Film::estimatedBytes(8192, 8192, 4000), 7e12);
    try {
        Film film(8192, 8192, 400, 800, 0.1, {one, one, one});
        ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("8192x8192 pixels with 4000 spectral bins"), std::string::npos) << e.what();
    }
    EXPECT_NO_THROW(Film(64, 64, 400, 700, 10, {one, one, one}));
}

}  // namespace
}  // namespace fluorosim
