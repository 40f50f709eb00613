#include <gtest/gtest.h>
#include <unistd.h>

#include <cstddef>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "core/errors.h"
#include "io/image_io.h"

namespace fluorosim {
namespace {

namespace fs = std::filesystem;

// Unique per test and process, so parallel ctest runs and concurrent builds never share a file.
fs::path tempFile(const std::string& name) {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    return fs::temp_directory_path() /
           ("fluorosim_" + std::string(info->name()) + "_" + std::to_string(::getpid()) + "_" + name);
}

// A directory that cannot exist, so writes into it must fail.
std::string missingDirPath(const std::string& file) {
    return (fs::temp_directory_path() / ("fluorosim_missing_dir_" + std::to_string(::getpid())) / file).string();
}

struct RemoveOnExit {
    fs::path path;
    ~RemoveOnExit() {
        std::error_code ec;
        fs::remove(path, ec);
    }
};

ExrImage makeImage(int width, int height, std::size_t bins) {
    ExrImage image;
    image.width = width;
    image.height = height;
    const std::size_t pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    for (std::size_t i = 0; i < 3 * pixels; ++i) image.rgb.push_back(0.25f * static_cast<float>(i) + 0.125f);
    SpectralLayer layer;
    for (std::size_t b = 0; b < bins; ++b) layer.wavelengthsNm.push_back(412.5 + 137.5 * static_cast<double>(b));
    for (std::size_t i = 0; i < bins * pixels; ++i) layer.values.push_back(-1.5f + 0.75f * static_cast<float>(i));
    image.spectral.push_back(layer);
    return image;
}

TEST(ImageIo, SpectralChannelNameFollowsFichetLayout) {
    EXPECT_EQ(spectralChannelName(550.0), "S0.550,000000nm");
    EXPECT_EQ(spectralChannelName(412.5), "S0.412,500000nm");
    EXPECT_EQ(spectralChannelName(1000.125), "S0.1000,125000nm");
}

TEST(ImageIo, SpectralChannelNameRejectsInvalidWavelength) {
    EXPECT_THROW(spectralChannelName(0.0), ConfigError);
    EXPECT_THROW(spectralChannelName(std::numeric_limits<double>::quiet_NaN()), ConfigError);
}

TEST(ImageIo, ExrRoundTripKeepsEveryChannelAndAttribute) {
    const int width = 3, height = 2;
    const std::size_t pixels = 6;
    ExrImage image = makeImage(width, height, 2);
    image.attributes["renderer"] = "fluorosim test";
    const RemoveOnExit cleanup{tempFile("roundtrip.exr")};
    const std::string path = cleanup.path.string();

    writeExr(path, image);
    const ExrChannels read = readExr(path);

    EXPECT_EQ(read.width, width);
    EXPECT_EQ(read.height, height);
    ASSERT_EQ(read.channels.size(), 5u);
    const char* rgbNames[3] = {"R", "G", "B"};
    for (std::size_t c = 0; c < 3; ++c) {
        ASSERT_EQ(read.channels.count(rgbNames[c]), 1u) << rgbNames[c];
        const std::vector<float>& values = read.channels.at(rgbNames[c]);
        ASSERT_EQ(values.size(), pixels);
        for (std::size_t p = 0; p < pixels; ++p) EXPECT_EQ(values[p], image.rgb[3 * p + c]) << rgbNames[c] << p;
    }
    const char* spectralNames[2] = {"S0.412,500000nm", "S0.550,000000nm"};
    for (std::size_t b = 0; b < 2; ++b) {
        ASSERT_EQ(read.channels.count(spectralNames[b]), 1u) << spectralNames[b];
        const std::vector<float>& values = read.channels.at(spectralNames[b]);
        ASSERT_EQ(values.size(), pixels);
        for (std::size_t p = 0; p < pixels; ++p)
            EXPECT_EQ(values[p], image.spectral[0].values[b * pixels + p]) << spectralNames[b] << p;
    }
    ASSERT_EQ(read.attributes.count("spectralLayoutVersion"), 1u);
    EXPECT_EQ(read.attributes.at("spectralLayoutVersion"), "1.0");
    ASSERT_EQ(read.attributes.count("emissiveUnits"), 1u);
    EXPECT_EQ(read.attributes.at("emissiveUnits"), "W.m^-2.sr^-1");
    ASSERT_EQ(read.attributes.count("renderer"), 1u);
    EXPECT_EQ(read.attributes.at("renderer"), "fluorosim test");
}

TEST(ImageIo, ExrLayerPrefixAndCallerAttributesOverrideDefaults) {
    ExrImage image = makeImage(2, 2, 1);
    image.spectral[0].prefix = "fluorescence";
    image.attributes["emissiveUnits"] = "W.m^-2.sr^-1.um^-1";
    const RemoveOnExit cleanup{tempFile("prefix.exr")};

    writeExr(cleanup.path.string(), image);
    const ExrChannels read = readExr(cleanup.path.string());

    EXPECT_EQ(read.channels.count("fluorescence.S0.412,500000nm"), 1u);
    EXPECT_EQ(read.attributes.at("emissiveUnits"), "W.m^-2.sr^-1.um^-1");
}

TEST(ImageIo, ExrMissingDirectoryThrowsIoErrorNamingPath) {
    const std::string path = missingDirPath("out.exr");
    try {
        writeExr(path, makeImage(3, 2, 2));
        FAIL() << "expected IoError";
    } catch (const IoError& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
}

TEST(ImageIo, ExrReadMissingFileThrowsIoErrorNamingPath) {
    const std::string path = missingDirPath("in.exr");
    try {
        readExr(path);
        FAIL() << "expected IoError";
    } catch (const IoError& e) {
        EXPECT_EQ(std::string(e.what()).rfind(path, 0), 0u) << e.what();
    }
}

TEST(ImageIo, ExrMismatchedSizesThrowConfigError) {
    const std::string path = tempFile("bad.exr").string();
    ExrImage badRgb = makeImage(3, 2, 2);
    badRgb.rgb.pop_back();
    EXPECT_THROW(writeExr(path, badRgb), ConfigError);

    ExrImage badSpectral = makeImage(3, 2, 2);
    badSpectral.spectral[0].values.push_back(1.0f);
    EXPECT_THROW(writeExr(path, badSpectral), ConfigError);

    ExrImage badSize = makeImage(3, 2, 2);
    badSize.width = 0;
    EXPECT_THROW(writeExr(path, badSize), ConfigError);

    ExrImage duplicate = makeImage(3, 2, 2);
    duplicate.spectral[0].wavelengthsNm[1] = duplicate.spectral[0].wavelengthsNm[0];
    EXPECT_THROW(writeExr(path, duplicate), ConfigError);

    EXPECT_FALSE(fs::exists(path));
}

TEST(ImageIo, PngPreviewWritesValidFile) {
    const RemoveOnExit cleanup{tempFile("preview.png")};
    std::vector<float> rgb = {0.0f, 0.5f, 1.0f, 2.0f, -1.0f, 0.01f};
    rgb[4] = std::numeric_limits<float>::quiet_NaN();  // must not fail the write

    writePngPreview(cleanup.path.string(), 2, 1, rgb, 1.0);

    std::ifstream in(cleanup.path, std::ios::binary);
    ASSERT_TRUE(in);
    unsigned char signature[8] = {};
    in.read(reinterpret_cast<char*>(signature), sizeof signature);
    const unsigned char expected[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    for (std::size_t i = 0; i < 8; ++i) EXPECT_EQ(signature[i], expected[i]) << i;
}

TEST(ImageIo, PngMissingDirectoryThrowsIoErrorNamingPath) {
    const std::string path = missingDirPath("preview.png");
    try {
        writePngPreview(path, 1, 1, {0.1f, 0.2f, 0.3f}, 1.0);
        FAIL() << "expected IoError";
    } catch (const IoError& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
}

TEST(ImageIo, PngMismatchedSizeThrowsConfigError) {
    EXPECT_THROW(writePngPreview(tempFile("bad.png").string(), 2, 2, {0.1f, 0.2f, 0.3f}, 1.0), ConfigError);
}

}  // namespace
}  // namespace fluorosim
