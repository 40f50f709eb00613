// OME-TIFF stacks: pixels and OME-XML read back through libtiff, XML escaping, the temporary file
// and rename, and errors for bad stacks and unwritable paths.
#include <gtest/gtest.h>

#include "support/cli_runner.h"
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "core/errors.h"
#include "optics/detector.h"
#include "optics/ome_tiff.h"
#include "optics/stack_files.h"

namespace fluorosim::optics {
namespace {
namespace fs = std::filesystem;

using fluorosim::testing::TempDir;
using fluorosim::testing::contains;

std::string unescape(const std::string& s) {
    static const std::vector<std::pair<std::string, std::string>> entities = {
        {"&lt;", "<"}, {"&gt;", ">"}, {"&quot;", "\""}, {"&apos;", "'"}, {"&#9;", "\t"}, {"&#10;", "\n"}, {"&#13;", "\r"}, {"&amp;", "&"}};
    std::string out;
    for (size_t i = 0; i < s.size();) {
        bool matched = false;
        for (const auto& [entity, text] : entities)
            if (s.compare(i, entity.size(), entity) == 0) {
                out += text;
                i += entity.size();
                matched = true;
                break;
            }
        if (!matched) out += s[i++];
    }
    return out;
}

// The index-th start tag <tag ...> (its text up to '>'), or "" if there are fewer.
std::string startTag(const std::string& xml, const std::string& tag, int index = 0) {
    size_t pos = 0;
    for (int i = 0;; ++i) {
        pos = xml.find("<" + tag + " ", pos);
        if (pos == std::string::npos) return "";
        if (i == index) return xml.substr(pos, xml.find('>', pos) - pos + 1);
        ++pos;
    }
}

int countTags(const std::string& xml, const std::string& tag) {
    int n = 0;
    for (size_t pos = xml.find("<" + tag + " "); pos != std::string::npos; pos = xml.find("<" + tag + " ", pos + 1)) ++n;
    return n;
}

// An attribute's unescaped value (values never contain a raw '"': it is escaped).
std::optional<std::string> attribute(const std::string& tag, const std::string& name) {
    const size_t pos = tag.find(" " + name + "=\"");
    if (pos == std::string::npos) return std::nullopt;
    const size_t start = pos + name.size() + 3;
    return unescape(tag.substr(start, tag.find('"', start) - start));
}

double numberAttribute(const std::string& tag, const std::string& name) {
    const auto v = attribute(tag, name);
    return v ? std::stod(*v) : -1;
}

StackMetadata twoChannelMetadata() {
    StackMetadata meta;
    meta.pixelSizeUm = 0.1625;
    meta.zStepUm = 0.5;
    meta.exposureS = 0.02;
    meta.channels = {{"GFP", 488, 525}, {"mCherry", 561, 610}};
    meta.description = "light-sheet test stack";
    meta.significantBits = 16;
    return meta;
}

// Checks the OME-XML of a stack written with twoChannelMetadata().
void checkOmeXml(const std::string& xml, int width, int height, int planes, const std::string& type) {
    ASSERT_EQ(xml.rfind("<?xml", 0), 0u) << xml;
    EXPECT_TRUE(contains(xml, "xmlns=\"http://www.openmicroscopy.org/Schemas/OME/2016-06\""));
    const std::string pixels = startTag(xml, "Pixels");
    ASSERT_FALSE(pixels.empty()) << xml;
    EXPECT_EQ(attribute(pixels, "DimensionOrder"), "XYZCT");
    EXPECT_EQ(attribute(pixels, "Type"), type);
    EXPECT_EQ(numberAttribute(pixels, "SizeX"), width);
    EXPECT_EQ(numberAttribute(pixels, "SizeY"), height);
    EXPECT_EQ(numberAttribute(pixels, "SizeZ"), planes);
    EXPECT_EQ(numberAttribute(pixels, "SizeC"), 2);
    EXPECT_EQ(numberAttribute(pixels, "SizeT"), 1);
    EXPECT_EQ(numberAttribute(pixels, "PhysicalSizeX"), 0.1625);
    EXPECT_EQ(numberAttribute(pixels, "PhysicalSizeY"), 0.1625);
    EXPECT_EQ(numberAttribute(pixels, "PhysicalSizeZ"), 0.5);
    EXPECT_EQ(attribute(pixels, "PhysicalSizeXUnit"), "\xC2\xB5m");  // µm, U+00B5
    EXPECT_EQ(attribute(pixels, "PhysicalSizeZUnit"), "\xC2\xB5m");
    ASSERT_EQ(countTags(xml, "Channel"), 2);
    EXPECT_EQ(attribute(startTag(xml, "Channel", 0), "Name"), "GFP");
    EXPECT_EQ(numberAttribute(startTag(xml, "Channel", 0), "ExcitationWavelength"), 488);
    EXPECT_EQ(numberAttribute(startTag(xml, "Channel", 0), "EmissionWavelength"), 525);
    EXPECT_EQ(attribute(startTag(xml, "Channel", 1), "Name"), "mCherry");
    EXPECT_EQ(numberAttribute(startTag(xml, "Channel", 1), "ExcitationWavelength"), 561);
    EXPECT_EQ(numberAttribute(startTag(xml, "Channel", 1), "EmissionWavelength"), 610);
    EXPECT_EQ(attribute(startTag(xml, "Channel", 1), "EmissionWavelengthUnit"), "nm");
    const std::string tiffData = startTag(xml, "TiffData");
    EXPECT_EQ(numberAttribute(tiffData, "IFD"), 0);
    EXPECT_EQ(numberAttribute(tiffData, "PlaneCount"), 2 * planes);
    // One Plane per page, in page order: Z fastest, then C.
    ASSERT_EQ(countTags(xml, "Plane"), 2 * planes);
    for (int page = 0; page < 2 * planes; ++page) {
        const std::string plane = startTag(xml, "Plane", page);
        EXPECT_EQ(numberAttribute(plane, "TheZ"), page % planes) << plane;
        EXPECT_EQ(numberAttribute(plane, "TheC"), page / planes) << plane;
        EXPECT_EQ(numberAttribute(plane, "TheT"), 0) << plane;
        EXPECT_EQ(numberAttribute(plane, "ExposureTime"), 0.02) << plane;
        EXPECT_EQ(attribute(plane, "ExposureTimeUnit"), "s") << plane;
    }
    EXPECT_TRUE(contains(xml, "<Description>light-sheet test stack</Description>"));
    EXPECT_EQ(xml.substr(xml.size() - 7), "</OME>\n");
}

TEST(OmeTiff, Uint16StackRoundTrip) {
    const TempDir dir;
    const int w = 7, h = 5, planes = 3, channels = 2;
    std::vector<uint16_t> data(static_cast<size_t>(w * h * planes * channels));
    for (size_t i = 0; i < data.size(); ++i) data[i] = static_cast<uint16_t>(i * 97 % 65536);
    data.back() = 65535;
    const fs::path path = dir.path() / "stack.ome.tif";
    writeOmeTiffUint16(path, w, h, planes, channels, data, twoChannelMetadata());

    const TiffStackInfo info = readTiffStack(path, true);
    EXPECT_EQ(info.pages, planes * channels);
    EXPECT_EQ(info.width, w);
    EXPECT_EQ(info.height, h);
    EXPECT_EQ(info.bitsPerSample, 16);
    EXPECT_EQ(info.sampleFormat, 1);
    ASSERT_EQ(info.pixels.size(), data.size());
    for (size_t i = 0; i < data.size(); ++i) ASSERT_EQ(info.pixels[i], data[i]) << "sample " << i;
    checkOmeXml(info.imageDescription, w, h, planes, "uint16");
    EXPECT_EQ(numberAttribute(startTag(info.imageDescription, "Pixels"), "SignificantBits"), 16);
    EXPECT_FALSE(fs::exists(path.string() + ".partial"));
}

TEST(OmeTiff, Float32StackRoundTrip) {
    const TempDir dir;
    const int w = 4, h = 6, planes = 2, channels = 2;
    std::vector<float> data(static_cast<size_t>(w * h * planes * channels));
    for (size_t i = 0; i < data.size(); ++i) data[i] = 0.1f * static_cast<float>(i) + 1e-3f;
    const fs::path path = dir.path() / "expected.ome.tif";
    writeOmeTiffFloat32(path, w, h, planes, channels, data, twoChannelMetadata());

    const TiffStackInfo info = readTiffStack(path, true);
    EXPECT_EQ(info.pages, planes * channels);
    EXPECT_EQ(info.bitsPerSample, 32);
    EXPECT_EQ(info.sampleFormat, 3);
    ASSERT_EQ(info.pixels.size(), data.size());
    for (size_t i = 0; i < data.size(); ++i) ASSERT_EQ(info.pixels[i], static_cast<double>(data[i])) << "sample " << i;
    checkOmeXml(info.imageDescription, w, h, planes, "float");
    EXPECT_FALSE(attribute(startTag(info.imageDescription, "Pixels"), "SignificantBits"));
}

TEST(OmeTiff, EscapesXmlText) {
    StackMetadata meta = twoChannelMetadata();
    meta.channels[0].name = "A&B <\"x\"> 'y'\tz\nw";
    meta.description = "5 < 6 & \"quotes\"\nsecond line";
    const std::string xml = omeXml(3, 3, 1, 2, "uint16", meta);
    EXPECT_FALSE(contains(xml, "<\"x\">"));
    EXPECT_EQ(attribute(startTag(xml, "Channel", 0), "Name"), meta.channels[0].name);
    EXPECT_TRUE(contains(xml, "<Description>5 &lt; 6 &amp; &quot;quotes&quot;&#10;second line</Description>"));
    // XML 1.0 has no way to carry other control characters.
    meta.channels[1].name = std::string("bell\x07");
    try {
        omeXml(3, 3, 1, 2, "uint16", meta);
        ADD_FAILURE() << "accepted a control character";
    } catch (const ConfigError& e) {
        EXPECT_TRUE(contains(e.what(), "channels[1].name")) << e.what();
    }
}

TEST(OmeTiff, UnwritablePathIsAnIoErrorNamingIt) {
    const TempDir dir;
    const std::vector<uint16_t> data(4, 1);
    StackMetadata meta;
    meta.channels = {{"c", 488, 520}};
    const fs::path missing = dir.path() / "no_such_dir" / "stack.ome.tif";
    try {
        writeOmeTiffUint16(missing, 2, 2, 1, 1, data, meta);
        ADD_FAILURE() << "wrote into a missing directory";
    } catch (const IoError& e) {
        EXPECT_TRUE(contains(e.what(), missing.string())) << e.what();
    }
    // The final name is an existing directory: the stack is written, the rename fails, and the
    // temporary file is removed.
    const fs::path isDir = dir.path() / "taken.ome.tif";
    fs::create_directories(isDir / "child");
    try {
        writeOmeTiffUint16(isDir, 2, 2, 1, 1, data, meta);
        ADD_FAILURE() << "replaced a directory";
    } catch (const IoError& e) {
        EXPECT_TRUE(contains(e.what(), isDir.string())) << e.what();
    }
    EXPECT_FALSE(fs::exists(isDir.string() + ".partial"));
    EXPECT_TRUE(fs::is_directory(isDir / "child"));
    EXPECT_THROW(readTiffStack(dir.path() / "absent.tif"), IoError);
    std::ofstream(dir.path() / "not_a.tif") << "plain text";
    EXPECT_THROW(readTiffStack(dir.path() / "not_a.tif"), IoError);
}

TEST(OmeTiff, ReplacesAnExistingStackWhole) {
    const TempDir dir;
    StackMetadata meta;
    meta.channels = {{"c", 488, 520}};
    const fs::path path = dir.path() / "s.ome.tif";
    writeOmeTiffUint16(path, 2, 2, 2, 1, std::vector<uint16_t>(8, 7), meta);
    writeOmeTiffUint16(path, 3, 1, 1, 1, std::vector<uint16_t>{1, 2, 3}, meta);
    const TiffStackInfo info = readTiffStack(path, true);
    EXPECT_EQ(info.pages, 1);
    EXPECT_EQ(info.pixels, (std::vector<double>{1, 2, 3}));
    // A rejected stack leaves the existing file alone.
    EXPECT_THROW(writeOmeTiffUint16(path, 3, 1, 1, 1, std::vector<uint16_t>{1, 2}, meta), ConfigError);
    EXPECT_EQ(readTiffStack(path, true).pixels, (std::vector<double>{1, 2, 3}));
    EXPECT_EQ(std::distance(fs::directory_iterator(dir.path()), fs::directory_iterator()), 1);
}

TEST(OmeTiff, RejectsBadStacks) {
    const TempDir dir;
    const fs::path path = dir.path() / "bad.ome.tif";
    StackMetadata meta;
    meta.channels = {{"c", 488, 520}};
    const std::vector<uint16_t> four(4, 0);
    auto message = [&](auto&& write) -> std::string {
        try {
            write();
        } catch (const ConfigError& e) {
            return e.what();
        }
        return "(accepted)";
    };
    EXPECT_TRUE(contains(message([&] { writeOmeTiffUint16(path, 2, 2, 2, 1, four, meta); }), "has 4 samples, expected 8"));
    EXPECT_TRUE(contains(message([&] { writeOmeTiffUint16(path, 0, 2, 1, 1, four, meta); }), "must be >= 1"));
    EXPECT_TRUE(contains(message([&] { writeOmeTiffUint16(path, 2, 1, 1, 2, four, meta); }), "lists 1 channels"));
    StackMetadata bad = meta;
    bad.pixelSizeUm = -0.1;
    EXPECT_TRUE(contains(message([&] { writeOmeTiffUint16(path, 2, 2, 1, 1, four, bad); }), "pixelSizeUm = -0.1"));
    bad = meta;
    bad.zStepUm = 0;
    EXPECT_TRUE(contains(message([&] { writeOmeTiffUint16(path, 2, 2, 1, 1, four, bad); }), "zStepUm = 0"));
    bad = meta;
    bad.exposureS = NAN;
    EXPECT_TRUE(contains(message([&] { writeOmeTiffUint16(path, 2, 2, 1, 1, four, bad); }), "exposureS = nan"));
    bad = meta;
    bad.channels[0].emissionNm = 0;
    EXPECT_TRUE(contains(message([&] { writeOmeTiffUint16(path, 2, 2, 1, 1, four, bad); }), "channels[0].emissionNm = 0"));
    EXPECT_FALSE(fs::exists(path));
}

// A detector stack as the acquisition code will write it: 2 channels x 5 planes of 64 x 48 noisy
// uint16 frames and the float32 expected photoelectrons. With FLUOROSIM_KEEP_OME_TIFF=<dir> the two
// files are also written to <dir> (for scripts/check-ome-tiff.py, Fiji, napari).
TEST(OmeTiff, DetectorStack) {
    const TempDir dir;
    const int w = 64, h = 48, planes = 5, channels = 2;
    const Detector det{DetectorOptions{}};
    StackMetadata meta = twoChannelMetadata();
    meta.exposureS = det.options().exposureS;
    meta.description = "Fluorosim detector stack (sCMOS defaults)";
    std::vector<uint16_t> counts;
    std::vector<float> expected;
    for (int c = 0; c < channels; ++c)
        for (int z = 0; z < planes; ++z) {
            std::vector<double> photons(static_cast<size_t>(w * h));
            for (int y = 0; y < h; ++y)
                for (int x = 0; x < w; ++x) {
                    const double r2 = (x - 32.0) * (x - 32.0) + (y - 24.0) * (y - 24.0);
                    photons[static_cast<size_t>(y * w + x)] = 2000.0 * (c + 1) * std::exp(-r2 / (2.0 * (4.0 + z) * (4.0 + z))) + 20;
                }
            const std::vector<double> e = det.expectedElectrons(det.photoelectrons(photons, meta.channels[c].emissionNm));
            const std::vector<uint16_t> frame = det.readOut(e, 77, static_cast<uint64_t>(c * planes + z));
            counts.insert(counts.end(), frame.begin(), frame.end());
            for (double v : e) expected.push_back(static_cast<float>(v));
        }
    std::vector<fs::path> dirs = {dir.path()};
    if (const char* keep = std::getenv("FLUOROSIM_KEEP_OME_TIFF")) dirs.emplace_back(keep);
    for (const fs::path& d : dirs) {
        writeOmeTiffUint16(d / "detector_stack.ome.tif", w, h, planes, channels, counts, meta);
        writeOmeTiffFloat32(d / "detector_expected.ome.tif", w, h, planes, channels, expected, meta);
    }
    const TiffStackInfo info = readTiffStack(dir.path() / "detector_stack.ome.tif", true);
    EXPECT_EQ(info.pages, planes * channels);
    ASSERT_EQ(info.pixels.size(), counts.size());
    for (size_t i = 0; i < counts.size(); ++i) ASSERT_EQ(info.pixels[i], counts[i]);
    EXPECT_EQ(readTiffStack(dir.path() / "detector_expected.ome.tif").pages, planes * channels);
}

// The preview's scale bar: a round length of at most a fifth of the field.
TEST(StackPreview, ScaleBarIsARoundFifthOfTheField) {
    EXPECT_DOUBLE_EQ(optics::previewScaleBarUm(0.40625, 256), 20);  // 104 um field
    EXPECT_DOUBLE_EQ(optics::previewScaleBarUm(0.40625, 64), 5);    // 26 um
    EXPECT_DOUBLE_EQ(optics::previewScaleBarUm(0.40625, 16), 1);    // 6.5 um
    EXPECT_DOUBLE_EQ(optics::previewScaleBarUm(6.5, 2048), 2000);   // 13.3 mm at 1x
}

}  // namespace
}  // namespace fluorosim::optics
