// SWC reading (errors name file, line, field and value) and the analytic volume of the surface
// model: soma spheres plus frusta, with neurites starting on the soma's surface.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>

#include "core/errors.h"
#include "morphology/swc.h"
#include "support/temp_dir.h"

namespace fluorosim {
namespace {

namespace fs = std::filesystem;
constexpr double kPi = std::numbers::pi;

// One folder per test process, removed at exit.
fs::path writeTemp(const std::string& name, const std::string& text) {
    static const testing::TempDir dir;
    return dir.write(name, text);
}

// The ConfigError message parseSwc gives for `text`, or "" if it parses.
std::string parseError(const std::string& text) {
    try {
        parseSwc(text, "cell.swc");
    } catch (const ConfigError& e) {
        return e.what();
    }
    return "";
}

void expectContains(const std::string& message, const std::string& part) {
    EXPECT_NE(message.find(part), std::string::npos) << "no \"" << part << "\" in: " << message;
}

TEST(Swc, ReadsInlineFileWithCommentsCrlfAndTabs) {
    const fs::path p = writeTemp("inline.swc",
                                 "# a comment\r\n"
                                 "\r\n"
                                 " 1 1 0 0 0 5 -1\r\n"
                                 "2\t3\t10.5\t0\t0\t1.\t1   # trailing comment\r\n"
                                 "3 3 20 +1e1 -2 0.5 2\r\n");
    const Morphology m = readSwc(p.string());
    fs::remove(p);
    EXPECT_EQ(m.source, p.string());
    ASSERT_EQ(m.samples.size(), 3u);
    EXPECT_EQ(m.samples[0].id, 1);
    EXPECT_EQ(m.samples[0].type, 1);
    EXPECT_EQ(m.samples[0].parent, -1);
    EXPECT_EQ(m.samples[0].line, 3);
    EXPECT_EQ(m.samples[1].type, 3);
    EXPECT_DOUBLE_EQ(m.samples[1].positionUm.x, 10.5);
    EXPECT_DOUBLE_EQ(m.samples[1].radiusUm, 1.0);
    EXPECT_EQ(m.samples[1].parent, 1);
    EXPECT_EQ(m.samples[2].line, 5);
    EXPECT_DOUBLE_EQ(m.samples[2].positionUm.y, 10.0);
    EXPECT_DOUBLE_EQ(m.samples[2].positionUm.z, -2.0);
}

TEST(Swc, MalformedLinesNameFileLineFieldAndValue) {
    const std::string head = "# header\n1 1 0 0 0 5 -1\n";  // the bad line is line 3
    struct Case {
        std::string line, field, value;
    };
    const Case cases[] = {
        {"2 3 1 2 3 0.5", "7 fields", "2 3 1 2 3 0.5"},
        {"2 3 1 2 3 0.5 1 9", "7 fields", "2 3 1 2 3 0.5 1 9"},
        {"2 3 abc 2 3 0.5 1", "\"x\"", "abc"},
        {"2 3 1 2 3 0.5x 1", "\"radius\"", "0.5x"},
        {"2 3 1 2 3 -1 1", "\"radius\"", "-1"},
        {"2 3 1 2 3 0 1", "\"radius\"", "0"},
        {"2 3 1 2 3 nan 1", "\"radius\"", "nan"},
        {"2 3 1 2 inf 0.5 1", "\"z\"", "inf"},
        {"2.5 3 1 2 3 0.5 1", "\"id\"", "2.5"},
        {"2 -3 1 2 3 0.5 1", "\"type\"", "-3"},
        {"2 3 1 2 3 0.5 -7", "\"parent\"", "-7"},
        {"2 3 1 2 3 0.5 2", "\"parent\"", "2"},
        {"2 3 1 2 3 0.5 99", "\"parent\"", "99"},
        {"1 3 1 2 3 0.5 -1", "\"id\"", "1"},
    };
    for (const Case& c : cases) {
        const std::string msg = parseError(head + c.line + "\n");
        ASSERT_FALSE(msg.empty()) << "accepted: " << c.line;
        expectContains(msg, "cell.swc:3:");
        expectContains(msg, c.field);
        expectContains(msg, c.value);
    }
}

TEST(Swc, CycleEmptyAndMissingFile) {
    const std::string cycle = parseError("1 1 0 0 0 5 -1\n2 3 1 0 0 1 3\n3 3 2 0 0 1 2\n");
    expectContains(cycle, "cell.swc:");
    expectContains(cycle, "cycle");
    expectContains(cycle, "\"parent\"");
    expectContains(parseError("# nothing but comments\n\n"), "cell.swc: no samples");

    const std::string missing = "/nonexistent/folder/neuron.swc";
    try {
        readSwc(missing);
        FAIL() << "expected IoError";
    } catch (const IoError& e) {
        expectContains(e.what(), missing);
    }
    const fs::path bad = writeTemp("bad.swc", "1 1 0 0 0 5 -1\n2 3 1 0 0 -0.5 1\n");
    try {
        readSwc(bad.string());
        FAIL() << "expected ConfigError";
    } catch (const ConfigError& e) {
        expectContains(e.what(), bad.string() + ":2:");
        expectContains(e.what(), "-0.5");
    }
    fs::remove(bad);
}

// Soma of radius 5 at the origin; a cylinder out of it along x; a cone and a frustum from its end.
std::string handBuilt(const std::string& soma) {
    return soma +
           "10 3 15 0 0 1 1\n"     // from the soma surface (5,0,0): cylinder L = 10, r = 1
           "11 3 15 20 0 0.5 10\n"  // frustum L = 20, r 1 -> 0.5
           "12 3 15 0 10 2 10\n";   // frustum L = 10, r 1 -> 2
}

double handBuiltVolume() {
    return 4.0 / 3.0 * kPi * 125 + kPi * 10 + kPi * 20 / 3 * (1 + 0.5 + 0.25) + kPi * 10 / 3 * (1 + 2 + 4);
}

TEST(Swc, AnalyticVolumeOfHandBuiltMorphology) {
    const Morphology single = parseSwc(handBuilt("1 1 0 0 0 5 -1\n"), "single");
    EXPECT_NEAR(analyticVolumeUm3(single), handBuiltVolume(), 1e-9 * handBuiltVolume());
    // NeuroMorpho's 3-point soma: the same sphere.
    const Morphology three = parseSwc(handBuilt("1 1 0 0 0 5 -1\n2 1 0 5 0 5 1\n3 1 0 -5 0 5 1\n"), "three");
    EXPECT_NEAR(analyticVolumeUm3(three), handBuiltVolume(), 1e-9 * handBuiltVolume());
    const auto pieces = morphologyPieces(three);
    ASSERT_EQ(pieces.size(), 4u);
    EXPECT_TRUE(pieces[0].sphere);
    EXPECT_DOUBLE_EQ(pieces[0].raUm, 5);
    // The neurite starts on the soma surface, towards the child.
    EXPECT_DOUBLE_EQ(pieces[1].aUm.x, 5);
    EXPECT_DOUBLE_EQ(pieces[1].raUm, 1);
    EXPECT_DOUBLE_EQ(pieces[1].rbUm, 1);

    // A two-sample soma is a frustum, and a neurite leaves from its parent sample's sphere.
    const Morphology two = parseSwc("1 1 0 0 0 3 -1\n2 1 0 0 4 2 1\n3 3 10 0 4 1 2\n", "two");
    EXPECT_NEAR(analyticVolumeUm3(two), kPi * 4 / 3 * (9 + 6 + 4) + kPi * 8, 1e-9);
    // A neurite sample inside the soma adds nothing.
    const Morphology inside = parseSwc("1 1 0 0 0 5 -1\n2 3 1 1 0 0.5 1\n", "inside");
    EXPECT_NEAR(analyticVolumeUm3(inside), 4.0 / 3.0 * kPi * 125, 1e-9);
}

TEST(Swc, MedianRadiusIgnoresSoma) {
    const Morphology m = parseSwc("1 1 0 0 0 9 -1\n2 3 10 0 0 0.1 1\n3 3 20 0 0 0.3 2\n4 3 30 0 0 0.2 3\n5 3 40 0 0 0.4 4\n", "m");
    EXPECT_DOUBLE_EQ(medianRadiusUm(m), 0.25);
}

TEST(Swc, ReadsNeuroMorphoSamples) {
    const std::string dir = FLUOROSIM_SOURCE_DIR "/samples/neurons/";
    // CRLF line ends and a 3-point soma.
    const Morphology a = readSwc(dir + "C010398B-P2.CNG.swc");
    EXPECT_EQ(a.samples.size(), 1347u);
    const auto pieces = morphologyPieces(a);
    ASSERT_FALSE(pieces.empty());
    EXPECT_TRUE(pieces[0].sphere);
    EXPECT_DOUBLE_EQ(pieces[0].raUm, 6.474);
    EXPECT_EQ(std::count_if(pieces.begin(), pieces.end(), [](const MorphologyPiece& p) { return p.sphere; }), 1);
    EXPECT_EQ(readSwc(dir + "C231296A-P3.CNG.swc").samples.size(), 2595u);
    EXPECT_EQ(readSwc(dir + "mp_ma_40984_gc2.CNG.swc").samples.size(), 353u);
}

TEST(Swc, PlacementRotatesAboutTheSomaThenMoves) {
    Morphology m = parseSwc("1 1 5 5 5 2 -1\n2 3 15 5 5 1 1\n3 3 15 5 9 0.5 2\n", "inline");
    const double before = analyticVolumeUm3(m);
    Placement p;
    p.rotationsDeg = {{'z', 90}, {'x', 90}};
    p.offsetUm = Vec3(100, 0, -1);
    place(m, p);
    // (10, 0, 0) from the soma turns to (0, 10, 0) about z, then to (0, 0, 10) about x; (10, 0, 4) to (0, -4, 10).
    auto near = [](const Vec3& a, const Vec3& b) { return std::abs(a.x - b.x) < 1e-12 && std::abs(a.y - b.y) < 1e-12 && std::abs(a.z - b.z) < 1e-12; };
    EXPECT_TRUE(near(m.samples[0].positionUm, Vec3(105, 5, 4)));
    EXPECT_TRUE(near(m.samples[1].positionUm, Vec3(105, 5, 14)));
    EXPECT_TRUE(near(m.samples[2].positionUm, Vec3(105, 1, 14)));
    EXPECT_EQ(m.samples[2].radiusUm, 0.5);
    EXPECT_NEAR(analyticVolumeUm3(m), before, 1e-9 * before);
}

}  // namespace
}  // namespace fluorosim
