// `fluorosim acquire` and `validate lightsheet` end to end, and the microscope's bad input: an NA
// above the immersion index, zero exposure, a bit depth outside 8-16, a filter that blocks the dye's
// emission (a warning), a sheet that misses the sample (a warning and an honestly empty stack), an
// unwritable output.
#include <gtest/gtest.h>

#include <regex>

#include <signal.h>

#include <nlohmann/json.hpp>
#include <tuple>

#include "optics/filter.h"
#include "optics/ome_tiff.h"
#include "support/fluorescent_scenes.h"
#include "support/cli_runner.h"

namespace fluorosim {
namespace {

using json = nlohmann::json;
using namespace testing;

const fs::path kBeads = fs::path(FLUOROSIM_SOURCE_DIR) / "samples" / "lightsheet" / "beads.json";

// Width and height of a PNG, from its IHDR chunk.
std::pair<int, int> pngSize(const fs::path& file) {
    const std::string bytes = readFile(file);
    auto be32 = [&](size_t at) {
        return static_cast<int>((static_cast<unsigned char>(bytes.at(at)) << 24) | (static_cast<unsigned char>(bytes.at(at + 1)) << 16) |
                                (static_cast<unsigned char>(bytes.at(at + 2)) << 8) | static_cast<unsigned char>(bytes.at(at + 3)));
    };
    return {be32(16), be32(20)};
}

// beads.json with absolute mesh paths, small (16 x 16 pixels, with one more bead in the middle of the
// field so that it holds one), after `edit`.
fs::path beads(const TempDir& dir, const std::function<void(json&)>& edit = {}) {
    json j = json::parse(readFile(kBeads));
    j["shapes"][0]["file"] = (kBeads.parent_path() / "bath.obj").string();
    json centre = j["shapes"][1];
    centre["name"] = "centre bead";
    centre["center"] = {"0.0004 mm", "-0.0003 mm", "0.0002 mm"};
    j["shapes"].push_back(centre);
    j["microscope"]["detector"]["width"] = 16;
    j["microscope"]["detector"]["height"] = 16;
    if (edit) edit(j);
    return dir.write("beads.json", j.dump());
}

TEST(AcquireCli, WritesOmeTiffStacks) {
    TempDir dir;
    const fs::path out = dir.path() / "stack.ome.tif";
    const auto r = runCli(dir, {"acquire", beads(dir).string(), "-o", out.string(), "--planes", "3", "--step", "1um", "--spp", "2", "--channels", "AF488"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const json summary = json::parse(r.out);
    EXPECT_EQ(summary["planes"], 3);
    EXPECT_NEAR(summary["pixel_size_um"].get<double>(), 6.5 / 16, 1e-12);
    const optics::TiffStackInfo stack = optics::readTiffStack(out, false);
    EXPECT_EQ(stack.pages, 3);
    EXPECT_EQ(stack.width, 16);
    EXPECT_EQ(stack.bitsPerSample, 16);
    EXPECT_TRUE(contains(stack.imageDescription, "PhysicalSizeZ=\"1\"")) << stack.imageDescription.substr(0, 600);
    // 6.5 um / 16 as it was meant, not 0.40625000000000006.
    EXPECT_TRUE(contains(stack.imageDescription, "PhysicalSizeX=\"0.40625\"")) << stack.imageDescription.substr(0, 600);
    EXPECT_TRUE(contains(stack.imageDescription, "ExcitationWavelength=\"488\"")) << stack.imageDescription.substr(0, 600);
    // The emission path's centre to 0.1 nm, not 525.4445925268271.
    EXPECT_TRUE(std::regex_search(stack.imageDescription, std::regex("EmissionWavelength=\"[0-9]+(\\.[0-9])?\""))) << stack.imageDescription.substr(0, 900);
    const optics::TiffStackInfo expected = optics::readTiffStack(dir.path() / "stack.expected.ome.tif", false);
    EXPECT_EQ(expected.pages, 3);
    EXPECT_EQ(expected.sampleFormat, 3);
}

// Quantities take any unit of their kind where a bare number carries the field's own ("exposure_s",
// "power_mW"): the same stack either way.
TEST(AcquireCli, ExposureAndPowerAcceptUnits) {
    TempDir dir;
    auto expected = [&](const std::function<void(json&)>& edit, const std::string& name) {
        const std::string out = (dir.path() / (name + ".ome.tif")).string();
        const auto r = runCli(dir, {"acquire", beads(dir, edit).string(), "-o", out, "--spp", "1", "--planes", "1"});
        EXPECT_EQ(r.exitCode, 0) << r.err;
        return readFile(dir.path() / (name + ".expected.ome.tif")).size() > 0 ? json::parse(r.out)["max_expected_electrons"].get<double>() : -1.0;
    };
    const double bare = expected([](json& j) {
        j["microscope"]["detector"]["exposure_s"] = 0.02;
        j["lights"][0]["power_mW"] = 0.004;
    }, "bare");
    const double units = expected([](json& j) {
        j["microscope"]["detector"]["exposure_s"] = "20 ms";
        j["lights"][0]["power_mW"] = "4 \xCE\xBCW";
    }, "units");
    EXPECT_GT(bare, 0);
    EXPECT_EQ(bare, units);
    const std::string out = (dir.path() / "bad.ome.tif").string();
    const auto r = runCli(dir, {"acquire", beads(dir, [](json& j) { j["microscope"]["detector"]["exposure_s"] = "20 mm"; }).string(), "-o", out});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"/microscope/detector/exposure_s", "20 mm", "units: s, ms, us, ns, min"});
}

// --exposure: a time replaces the scene's; auto:F scales the stack to put its brightest pixel at F of the
// full well, says what it chose, and writes that exposure into the summary and the OME metadata.
TEST(AcquireCli, ExposureAutoSaysWhatItChose) {
    TempDir dir;
    const std::string out = (dir.path() / "auto.ome.tif").string();
    auto r = runCli(dir, {"acquire", beads(dir).string(), "-o", out, "--spp", "2", "--planes", "2", "--exposure", "auto:0.4"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "exposure auto:")) << r.err;
    const json summary = json::parse(r.out);
    const double exposure = summary["exposure_s"].get<double>(), fullWell = summary["full_well_electrons"].get<double>();
    EXPECT_EQ(summary["exposure_auto"]["fraction"], 0.4);
    EXPECT_NEAR(exposure, 0.01 * summary["exposure_auto"]["factor"].get<double>(), 1e-12);  // the beads scene's 10 ms
    // The brightest pixel (with its dark electrons) sits at 40 % of the full well, unless a larger one is
    // a Monte Carlo outlier, which does not set the exposure.
    EXPECT_GE(summary["max_expected_electrons"].get<double>(), 0.4 * fullWell * (1 - 1e-5));
    const optics::TiffStackInfo stack = optics::readTiffStack(out, false);
    const size_t at = stack.imageDescription.find("ExposureTime=\"");
    ASSERT_NE(at, std::string::npos) << stack.imageDescription.substr(0, 800);
    EXPECT_NEAR(std::stod(stack.imageDescription.substr(at + 14)), exposure, 1e-6 * exposure);
    r = runCli(dir, {"acquire", beads(dir).string(), "-o", out, "--spp", "1", "--planes", "1", "--exposure", "auto:3"});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"--exposure", "auto:3"});
    r = runCli(dir, {"acquire", beads(dir).string(), "-o", out, "--spp", "1", "--planes", "1", "--exposure", "10ms"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NEAR(json::parse(r.out)["exposure_s"].get<double>(), 0.01, 1e-15);
}

// A channel is warned about only when it sees almost none of the dyes its own lasers excite, and only
// when it is acquired: two channels that each block the other's dye say nothing.
TEST(AcquireCli, FilterWarningsNameOnlyAChannelBlindToItsOwnDyes) {
    TempDir dir;
    auto run = [&](const std::string& redFilter, std::vector<std::string> extra) {
        const fs::path scene = beads(dir, [&](json& j) {
            j["media"]["red"] = json{{"ior", 1.33}, {"dyes", json::array({json{{"dye", "AF594"}, {"concentration", "100 uM"}}})}};
            j["shapes"].push_back(json{{"type", "sphere"}, {"center", {"0 mm", "0 mm", "0 mm"}}, {"radius", "0.1 um"}, {"interior", "red"}, {"exterior", "water"}});
            j["lights"].push_back(j["lights"][0]);
            j["lights"][1]["wavelength"] = "561 nm";
            j["microscope"]["channels"] = json::array({json{{"name", "green"}, {"emission_filter", "semrock_FF01-525-45"}, {"lights", {0}}},
                                                       json{{"name", "red"}, {"emission_filter", redFilter}, {"lights", {1}}}});
        });
        std::vector<std::string> args{"acquire", scene.string(), "-o", (dir.path() / "s.ome.tif").string(), "--spp", "1", "--planes", "1"};
        args.insert(args.end(), extra.begin(), extra.end());
        return runCli(dir, args);
    };
    auto r = run("semrock_FF01-609-54", {});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_FALSE(contains(r.err, "emission")) << r.err;
    // The preview: each channel's x-y projection and their merge, 16 pixels wide with 4 between; one
    // plane has no x-z panel.
    EXPECT_EQ(pngSize(dir.path() / "s.preview.png"), std::make_pair(3 * 16 + 2 * 4, 16));
    r = run("semrock_FF01-525-45", {});  // the red channel behind the green filter: the real mistake
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "warning: channel \"red\": its laser lines (561 nm) excite alexa_fluor_594 (47 % of its peak")) << r.err;
    EXPECT_FALSE(contains(r.err, "channel \"green\"")) << r.err;
    r = run("semrock_FF01-525-45", {"--channels", "green"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_FALSE(contains(r.err, "channel \"red\"")) << r.err;
}

// The objective's immersion index and the medium its rays cross must agree; a dry objective set over a
// water-filled camera medium used to give a stack identical to the water objective's without a word.
TEST(AcquireCli, AnImmersionIndexUnlikeTheCameraMediumIsWarnedAbout) {
    TempDir dir;
    const auto r = runCli(dir, {"acquire", beads(dir, [](json& j) { j["microscope"]["objective"]["immersion_index"] = 1.0; }).string(), "-o",
                                (dir.path() / "s.ome.tif").string(), "--spp", "1", "--planes", "1"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "warning: objective immersion_index 1 differs from the index 1.33 of the camera's medium \"water\"")) << r.err;
}

// Set-ups that would render for minutes an image that means nothing are caught before rendering, with
// numbers: planes beyond the specimen (each of them, not only plane 0), a sheet off the focal plane or far
// thicker than the depth of field, seconds that were meant as milliseconds, camera rays that start in
// tissue, and (refused) in a scattering medium that nothing bounds.
TEST(AcquireCli, SetUpMistakesAreCaughtBeforeRendering) {
    TempDir dir;
    const std::string out = (dir.path() / "s.ome.tif").string();
    auto run = [&](const std::function<void(json&)>& edit, std::vector<std::string> extra = {"--planes", "1"}) {
        std::vector<std::string> args{"acquire", beads(dir, edit).string(), "-o", out, "--spp", "1"};
        args.insert(args.end(), extra.begin(), extra.end());
        return runCli(dir, args);
    };
    auto wide = [](json& j) { j["microscope"]["detector"]["width"] = j["microscope"]["detector"]["height"] = 64; };
    auto r = run(wide);
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_FALSE(contains(r.err, "warning")) << r.err;
    // 6 planes 5 um apart over beads within 3 um of the focus: only the middle two planes meet them.
    r = run(wide, {"--planes", "6", "--step", "5um"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "warning: planes 0-1 (-12.5 um to -7.5 um from the focus): the field of view (26 um x 26 um) meets no dyed shape"))
        << r.err;
    EXPECT_TRUE(contains(r.err, "warning: planes 4-5 (7.5 um to 12.5 um from the focus)")) << r.err;
    EXPECT_FALSE(contains(r.err, "plane 2")) << r.err;
    // One channel, no merge; 6 planes 5 um apart are deep enough for the x-z panel (12 rows a plane).
    EXPECT_EQ(pngSize(dir.path() / "s.preview.png"), std::make_pair(64, 64 + 4 + 6 * 12));
    r = run([&](json& j) {
        wide(j);
        j["lights"][0]["waist"] = "3 mm";
    });
    EXPECT_TRUE(contains(r.err, "light 0's waist 3000 um is")) << r.err;
    EXPECT_TRUE(contains(r.err, "times the objective's depth of field")) << r.err;
    r = run([&](json& j) {
        wide(j);
        j["lights"][0]["center"] = {"0 mm", "0 mm", "0.05 mm"};
    });
    EXPECT_TRUE(contains(r.err, "the focal plane lies 50 um from the centre plane of light 0 (waist 1.5 um)")) << r.err;
    r = run([&](json& j) {
        wide(j);
        j["microscope"]["detector"]["exposure_s"] = 20;
        j["lights"][0]["power_mW"] = "5 nW";
    });
    EXPECT_TRUE(contains(r.err, "exposure 20 s is long for one plane")) << r.err;
    r = run([&](json& j) {
        wide(j);
        j["media"]["water"]["sigma_s"] = "1 /mm";
    });
    EXPECT_TRUE(contains(r.err, "the objective's front (working distance 200 um above plane 0) lies inside the scattering medium \"water\"")) << r.err;
    // An adaptive run that stops at its path limit says how far from its noise target it stayed.
    r = run(
        [&](json& j) {  // one 3 um bead fills the field; every pixel's image a Monte Carlo estimate
            json bead = j["shapes"][1];
            bead["center"] = {"0 mm", "0 mm", "0 mm"};
            bead["radius"] = "3 um";
            j["shapes"] = json::array({j["shapes"][0], bead});
            j["media"]["bead"]["dyes"][0]["concentration"] = "10 uM";
        },
        {"--planes", "1", "--estimator", "path", "--noise-ratio", "0.01", "--max-spp", "2"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "warning: noise target 0.01 missed: the Monte Carlo error over the camera's noise is")) << r.err;
    EXPECT_TRUE(contains(r.err, "paths per pixel on average (--max-spp 2)")) << r.err;
    r = run([&](json& j) {
        j["media"]["water"]["sigma_s"] = "1 /mm";
        j["shapes"].erase(0);  // no bath: the scattering camera medium fills space
    });
    EXPECT_EQ(r.exitCode, 2) << r.err;
    expectOneLineError(r, {"lies in the scattering medium \"water\" and no surface bounds it"});
}

TEST(AcquireCli, BadMicroscopeInputIsRejected) {
    TempDir dir;
    const std::string out = (dir.path() / "s.ome.tif").string();
    auto run = [&](const std::function<void(json&)>& edit) { return runCli(dir, {"acquire", beads(dir, edit).string(), "-o", out, "--spp", "1", "--planes", "1"}); };
    auto r = run([](json& j) { j["microscope"]["objective"]["na"] = 1.4; });
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"na 1.4", "immersion index 1.33"});
    r = run([](json& j) { j["microscope"]["detector"]["exposure_s"] = 0; });
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"microscope/detector", "exposure"});
    r = run([](json& j) { j["microscope"]["detector"]["bit_depth"] = 20; });
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"microscope/detector", "20"});
    r = runCli(dir, {"acquire", beads(dir).string(), "-o", out, "--spp", "1", "--planes", "1", "--channels", "mCherry"});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"--channels", "\"mCherry\""});
    r = run([](json& j) { j["microscope"]["detector"]["exposure"] = 0.1; });
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"microscope/detector", "unknown field \"exposure\""});
    r = runCli(dir, {"acquire", beads(dir).string(), "-o", (dir.path() / "missing" / "s.ome.tif").string(), "--spp", "1", "--planes", "1"});
    EXPECT_EQ(r.exitCode, 3);
    expectOneLineError(r, {"missing", "does not exist"});
}

TEST(AcquireCli, BlockingFilterAndMissedSheetWarn) {
    TempDir dir;
    const std::string out = (dir.path() / "s.ome.tif").string();
    auto r = runCli(dir, {"acquire", beads(dir, [](json& j) {
                              j["microscope"]["channels"][0]["emission_filter"] = json{{"center", "420 nm"}, {"fwhm", "10 nm"}};
                          }).string(),
                          "-o", out, "--spp", "1", "--planes", "1"});
    EXPECT_EQ(r.exitCode, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "warning: channel \"AF488\"")) << r.err;
    // The sheet 1 mm above the beads: every plane empty, said so, and the stack still written.
    r = runCli(dir, {"acquire", beads(dir, [](json& j) { j["lights"][0]["center"] = {"0 mm", "0 mm", "1 mm"}; }).string(), "-o", out, "--spp", "1",
                     "--planes", "2"});
    EXPECT_EQ(r.exitCode, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "plane 0: no signal")) << r.err;
    EXPECT_TRUE(fs::exists(out));
}

// Widefield epi-illumination (for comparison) lights every depth: a plane 2 µm above the highest bead
// collects the beads' defocused light.
TEST(AcquireCli, WidefieldLightsOutOfFocusBeads) {
    TempDir dir;
    const std::string out = (dir.path() / "s.ome.tif").string();
    auto far = [](json& j) {
        j["microscope"]["detector"]["width"] = j["microscope"]["detector"]["height"] = 64;  // the whole field of beads
        j["microscope"]["focus"]["center"] = {"0 mm", "0 mm", "0.005 mm"};
        j["lights"][0]["center"] = {"0 mm", "0 mm", "0.005 mm"};
    };
    const auto r = runCli(dir, {"acquire", beads(dir, [&](json& j) {
                                   far(j);
                                   j["lights"][0] = json{{"type", "widefield"}, {"wavelength", "488 nm"}, {"power_mW", 0.01},
                                                         {"direction", {0, 0, -1}}, {"center", {"0 mm", "0 mm", "0 mm"}}, {"field_diameter", "0.1 mm"}};
                               }).string(),
                     "-o", out, "--spp", "16", "--planes", "1"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_FALSE(contains(r.err, "no signal")) << r.err;
    EXPECT_GT(json::parse(r.out)["max_expected_electrons"].get<double>(), 1.0);
}

TEST(ValidateLightSheetCli, FittedWidthsFollowTheGaussianBeam) {
    TempDir dir;
    const fs::path out = dir.path() / "sheet.json";
    const auto r = runCli(dir, {"validate", "lightsheet", "--wavelength", "561", "--waist", "3", "--n", "1.33", "-o", out.string()});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const json j = json::parse(readFile(out));
    const double zR = j.at("rayleigh_range_um").get<double>();
    EXPECT_NEAR(zR, 3.14159265 * 9 * 1.33 / 0.561 * 1e-3 * 1e3, 1e-6 * zR);
    const json& x = j.at("positions_um");
    EXPECT_LE(x.front().get<double>(), -zR);
    EXPECT_GE(x.back().get<double>(), zR);
    for (size_t i = 0; i < x.size(); ++i) {
        const double w = 3 * std::sqrt(1 + std::pow(x.at(i).get<double>() / zR, 2));
        EXPECT_NEAR(j.at("widths_um").at(i).get<double>() / w, 1.0, 0.02) << "at x = " << x.at(i);
    }
}


TEST(ValidateLightSheetCli, BadArgumentsNameTheOption) {
    TempDir dir;
    const std::string out = (dir.path() / "s.json").string();
    auto r = runCli(dir, {"validate", "lightsheet", "--wavelength", "488", "--waist", "0", "-o", out});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"--waist"});
    r = runCli(dir, {"validate", "lightsheet", "--wavelength", "2000", "--waist", "2", "-o", out});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"--wavelength"});
    r = runCli(dir, {"validate", "lightsheet", "--wavelength", "488", "--waist", "2", "--sigma-s", "-1/mm", "-o", out});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"--sigma-s", "-1/mm"});
    r = runCli(dir, {"validate", "lightsheet", "--wavelength", "488", "--waist", "2", "-o", (dir.path() / "no" / "s.json").string()});
    EXPECT_EQ(r.exitCode, 3);
    expectOneLineError(r, {"does not exist"});
}

// In scattering tissue the light scattered out of the sheet builds up with depth: the contrast between
// the sheet and 3 w(x) beside it falls (docs/validation.md, section 10, has the full plot).
TEST(ValidateLightSheetCli, ScatteringLowersContrastWithDepth) {
    TempDir dir;
    const fs::path out = dir.path() / "depth.json";
    const auto r = runCli(dir, {"validate", "lightsheet", "--wavelength", "488", "--waist", "5", "--sigma-s", "5/mm", "--samples", "1024",
                                "--positions", "3", "-o", out.string()});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const json j = json::parse(readFile(out));
    const json& c = j.at("contrast_at_3w");
    EXPECT_GT(c.at(0).get<double>(), 10 * c.at(2).get<double>());
    // The thickness is compared half way (0.5 mm: 8.0 um against 5.9 um unscattered at 1024 to 16384
    // samples); at the far end the profile is nearly flat (contrast about 2), so its half-maximum width is
    // ill-conditioned at this sample count (13 to 43 um).
    EXPECT_GT(j.at("fwhm_um").at(1).get<double>(), 1.2 * j.at("unscattered_fwhm_um").at(1).get<double>());
}

// Bleed-through between channels: an AF488 bead, a "green" channel (488 nm sheet, 525/45) and a "red"
// one lit by both sheets at once (609/54). The bead shows up in the red channel through its emission
// tail, in the ratio of the filters' overlap with its emission, ∫ f T_609 / ∫ f T_525 (its tabulated
// absorption at 561 nm is 0). A second, AF594 bead is left out: the diffraction PSF's tail carries a
// few per cent of its light across any crop.
TEST(AcquireCli, ChannelsShowBleedThroughBetweenDyes) {
    TempDir dir;
    json j = json::parse(readFile(kBeads));
    j["shapes"] = json::array({json{{"type", "mesh"}, {"file", (kBeads.parent_path() / "bath.obj").string()}, {"unit", "um"}, {"interior", "water"}},
                               json{{"type", "sphere"}, {"center", {"0 mm", "0 mm", "0 mm"}}, {"radius", "1 um"}, {"interior", "green"}, {"exterior", "water"}}});
    j["media"]["green"] = json{{"ior", 1.33}, {"dyes", json::array({json{{"dye", "AF488"}, {"concentration", "100 uM"}}})}};
    j["media"].erase("bead");
    j["lights"][0]["waist"] = "3 um";
    j["lights"].push_back(j["lights"][0]);
    j["lights"][1]["wavelength"] = "561 nm";
    j["microscope"]["detector"]["width"] = 96;
    j["microscope"]["detector"]["height"] = 96;
    j["microscope"]["channels"] = json::array({json{{"name", "green"}, {"emission_filter", "semrock_FF01-525-45"}, {"lights", {0}}},
                                               json{{"name", "red"}, {"emission_filter", "semrock_FF01-609-54"}, {"lights", {0, 1}}}});
    const fs::path scene = dir.write("two.json", j.dump());
    const fs::path out = dir.path() / "two.ome.tif";
    const auto r = runCli(dir, {"acquire", scene.string(), "-o", out.string(), "--planes", "1", "--spp", "256"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const optics::TiffStackInfo e = optics::readTiffStack(dir.path() / "two.expected.ome.tif", true);
    const optics::TiffStackInfo se = optics::readTiffStack(dir.path() / "two.stderr.ome.tif", true);
    ASSERT_EQ(e.pages, 2);
    ASSERT_EQ(se.pages, 2);
    // Electrons above the dark level over the whole image of each channel, and their Monte Carlo
    // variance (pixels are independent estimates). The field (±19.5 um) holds all but the PSF's far tail,
    // about 0.5 % in either channel (2/(π² v) per edge), so their ratio is the spectral one to 1e-3.
    const double dark = 0.5 * 0.01;
    auto wholeImage = [&](int channel) {
        double sum = 0, variance = 0;
        for (int y = 0; y < 96; ++y)
            for (int x = 0; x < 96; ++x) {
                const size_t i = static_cast<size_t>(channel) * 96 * 96 + static_cast<size_t>(y * 96 + x);
                sum += e.pixels[i] - dark;
                variance += se.pixels[i] * se.pixels[i];
            }
        return std::pair{sum, variance};
    };
    const auto [green, greenVariance] = wholeImage(0);
    const auto [red, redVariance] = wholeImage(1);
    const double ratio = red / green;
    const double ratioStderr = ratio * std::sqrt(greenVariance / (green * green) + redVariance / (red * red));
    const Fluorophore af488 = databaseDye("AF488");
    const optics::Filter f525 = optics::Filter::fromDatabase(database(), "semrock_FF01-525-45");
    const optics::Filter f609 = optics::Filter::fromDatabase(database(), "semrock_FF01-609-54");
    double in525 = 0, in609 = 0;
    for (double l = 450; l < 750; l += 0.1) {
        in525 += af488.emissionPdf(l) * f525.transmission(l);
        in609 += af488.emissionPdf(l) * f609.transmission(l);
    }
    std::printf("  AF488 bead: green %.4g e-, red %.4g e-, bleed-through %.4f +- %.4f, spectral overlap ratio %.4f\n", green, red, ratio,
                ratioStderr, in609 / in525);
    ASSERT_LT(ratioStderr, 0.1 * ratio);  // the check below must be able to fail
    // The image is nearly all computed: the tolerance is the field's edge losses (1e-3, above) and 4
    // standard errors of the paths' part.
    EXPECT_NEAR(ratio, in609 / in525, 1e-3 * ratio + 4 * ratioStderr);
}

// Random streams are keyed by channel name and plane: acquiring one channel alone gives the same
// plane, bit for bit, as the full acquisition.
TEST(AcquireCli, OneChannelAloneMatchesTheFullAcquisition) {
    TempDir dir;
    const fs::path scene = beads(dir, [](json& j) {
        j["microscope"]["detector"]["width"] = j["microscope"]["detector"]["height"] = 40;
        j["microscope"]["channels"].push_back(json{{"name", "wide"}, {"emission_filter", json{{"center", "560 nm"}, {"fwhm", "80 nm"}}}});
    });
    const fs::path both = dir.path() / "both.ome.tif", one = dir.path() / "one.ome.tif";
    ASSERT_EQ(runCli(dir, {"acquire", scene.string(), "-o", both.string(), "--planes", "2", "--spp", "32"}).exitCode, 0);
    ASSERT_EQ(runCli(dir, {"acquire", scene.string(), "-o", one.string(), "--planes", "2", "--spp", "32", "--channels", "wide"}).exitCode, 0);
    const auto a = optics::readTiffStack(dir.path() / "both.expected.ome.tif", true), b = optics::readTiffStack(dir.path() / "one.expected.ome.tif", true);
    ASSERT_EQ(a.pages, 4);
    ASSERT_EQ(b.pages, 2);
    const std::vector<double> wide(a.pixels.begin() + static_cast<std::ptrdiff_t>(a.pixels.size() / 2), a.pixels.end());
    EXPECT_EQ(wide, b.pixels);
    EXPECT_GT(*std::max_element(b.pixels.begin(), b.pixels.end()), 0.1);
}

TEST(AcquireCli, BadNumbersAreRejectedNotCast) {
    TempDir dir;
    const std::string out = (dir.path() / "s.ome.tif").string();
    auto run = [&](const std::function<void(json&)>& edit, std::vector<std::string> extra = {}) {
        std::vector<std::string> args{"acquire", beads(dir, edit).string(), "-o", out, "--spp", "1"};
        if (std::find(extra.begin(), extra.end(), "--planes") == extra.end()) args.insert(args.end(), {"--planes", "1"});
        args.insert(args.end(), extra.begin(), extra.end());
        return runCli(dir, args);
    };
    const std::vector<std::tuple<std::function<void(json&)>, std::vector<std::string>, std::vector<std::string>>> cases{
        {[](json& j) { j["microscope"]["stack"]["planes"] = 1e308; }, {}, {"/microscope/stack/planes", "[1, 4096]"}},
        {[](json& j) { j["microscope"]["stack"]["planes"] = 2.7; }, {}, {"/microscope/stack/planes", "integer"}},
        {[](json& j) { j["microscope"]["detector"]["bit_depth"] = 1e10; }, {}, {"/microscope/detector/bit_depth", "[8, 16]"}},
        {[](json& j) { j["microscope"]["detector"]["width"] = 0; }, {}, {"/microscope/detector/width", "[1, 8192]"}},
        {[](json& j) { j["microscope"]["focus"]["toward_objective"] = {0, 0, 0}; }, {}, {"/microscope/focus/toward_objective", "non-zero"}},
        {[](json& j) { j["microscope"]["channels"][0]["lights"] = {4294967296.0}; }, {}, {"/microscope/channels/0/lights/0", "[0, 0]"}},
        {[](json& j) { j["microscope"]["channels"][0]["lights"] = 0; }, {}, {"/microscope/channels/0/lights", "array"}},
        {[](json& j) { j["microscope"]["channels"].push_back(j["microscope"]["channels"][0]); }, {}, {"/microscope/channels/1/name", "two channels"}},
        {{}, {"--threads", "65537"}, {"--threads", "65537"}},
        {{}, {"--seed", "-1"}, {"--seed", "-1"}},
        {{}, {"--planes", "0"}, {"--planes", "0"}},
        {{}, {"--step", "-1um"}, {"--step"}},
        {{}, {"--estimator", "fast"}, {"--estimator", "fast"}},
        {{}, {"--direct-spp", "32"}, {"--direct-spp", "removed"}},
        {{}, {"--noise-ratio", "-0.5"}, {"--noise-ratio", "-0.5"}},
        {{}, {"--noise-ratio", "inf"}, {"--noise-ratio", "inf"}},
        {{}, {"--max-spp", "64"}, {"--max-spp", "--noise-ratio"}},
        {{}, {"--noise-ratio", "0.5", "--max-spp", "0"}, {"--max-spp", "[spp = 1", "0"}},
        {{}, {"--field-photons", "1"}, {"--field-photons", "[2, 2^40]", "1"}},
        {{}, {"--field-photons", "-5"}, {"--field-photons", "-5"}},
        {{}, {"--field-margin-um", "-3"}, {"--field-margin-um", "[0, 10000]", "-3"}},
        {{}, {"--field-reach-um", "nan"}, {"--field-reach-um", "nan"}},
        {{}, {"--field-diffuse-um", "-3"}, {"--field-diffuse-um", "[1, 1000]", "-3"}},
        {{}, {"--field-diffuse-um", "0.5"}, {"--field-diffuse-um", "[1, 1000]", "0.5"}},
        {{}, {"--emission-photons", "1"}, {"--emission-photons", "[2, 2^40]", "1"}},
        {{}, {"--emission-photons", "-3"}, {"--emission-photons", "-3"}},
        {{}, {"--emission-track-um", "-1"}, {"--emission-track-um", "[0, 1000]", "-1"}},
        {{}, {"--emission-track-um", "nan"}, {"--emission-track-um", "nan"}},
    };
    for (const auto& [edit, extra, parts] : cases) {
        const auto r = run(edit, extra);
        EXPECT_EQ(r.exitCode, 2) << parts[0] << "\n" << r.err;
        SCOPED_TRACE(parts[0]);
        expectOneLineError(r, parts);
    }
    {
        const auto r = runCli(dir, {"acquire", beads(dir, [](json&) {}).string(), "-o", out, "--planes", "1", "--spp", "0"});
        EXPECT_EQ(r.exitCode, 2) << r.err;
        expectOneLineError(r, {"--spp", "0"});
    }
    // A stack of 8192 x 8192 pixels and 4096 planes is refused before anything is allocated.
    const auto r = run([](json& j) {
        j["microscope"]["detector"]["width"] = 8192;
        j["microscope"]["detector"]["height"] = 8192;
        j["microscope"]["stack"]["planes"] = 4096;
    }, {"--planes", "4096"});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"/microscope", "8192 x 8192", "GiB", "cap"});
}

// Starts the CLI in the background; returns the path of a file that receives its exit code.
struct BackgroundRun {
    fs::path pidFile, rcFile;
    long pid() const { return std::stol(readFile(pidFile)); }
    bool finished() const { return fs::exists(rcFile) && !readFile(rcFile).empty(); }
    int exitCode() const { return std::stoi(readFile(rcFile)); }
};
BackgroundRun startCli(const TempDir& dir, const std::vector<std::string>& args) {
    BackgroundRun b{dir.path() / "pid.txt", dir.path() / "rc.txt"};
    fs::remove(b.pidFile);
    fs::remove(b.rcFile);
    std::string cmd = quote(FLUOROSIM_CLI);
    for (const auto& a : args) cmd += " " + quote(a);
    const std::string script = cmd + " </dev/null >/dev/null 2>" + quote((dir.path() / "bg_stderr.txt").string()) + " & p=$!; echo $p > " +
                               quote((dir.path() / "pid.tmp").string()) + "; mv " + quote((dir.path() / "pid.tmp").string()) + " " +
                               quote(b.pidFile.string()) + "; wait $p; echo $? > " + quote((dir.path() / "rc.tmp").string()) + "; mv " +
                               quote((dir.path() / "rc.tmp").string()) + " " + quote(b.rcFile.string());
    std::system(("sh -c " + quote(script) + " &").c_str());
    return b;
}

// Waits for `condition`; the limit only keeps a broken build from hanging the suite (it is a failure of
// the behaviour, not a speed measurement).
bool waitFor(const std::function<bool()>& condition) {
    for (int i = 0; i < 60000; ++i) {
        if (condition()) return true;
        ::usleep(10000);
    }
    return false;
}

size_t checkpointRecords(const fs::path& checkpoint, size_t recordBytes) {
    const std::string text = readFile(checkpoint);
    const size_t first = text.find('\n'), second = first == std::string::npos ? first : text.find('\n', first + 1);
    if (second == std::string::npos) return 0;
    return (text.size() - second - 1) / recordBytes;
}

// SIGTERM in the middle of a stack keeps every finished plane: the checkpoint holds them, the complete
// planes are written as valid stacks, and --resume finishes the run to exactly what an uninterrupted
// run with the same seed gives.
TEST(AcquireCli, InterruptedStackResumesToTheSameResult) {
    TempDir dir;
    const fs::path scene = beads(dir);
    const std::vector<std::string> common{"--planes", "24", "--step", "0.5um", "--spp", "24", "--threads", "1", "--seed", "3"};
    auto args = [&](const std::string& out, bool resume) {
        std::vector<std::string> a{"acquire", scene.string(), "-o", (dir.path() / out).string()};
        a.insert(a.end(), common.begin(), common.end());
        if (resume) a.push_back("--resume");
        return a;
    };
    ASSERT_EQ(runCli(dir, args("full.ome.tif", false), 600).exitCode, 0);

    const BackgroundRun run = startCli(dir, args("cut.ome.tif", false));
    const fs::path checkpoint = dir.path() / "cut.checkpoint";
    const size_t recordBytes = 16 + 2 * sizeof(double) * 16 * 16;
    ASSERT_TRUE(waitFor([&] { return fs::exists(run.pidFile) && fs::exists(checkpoint) && checkpointRecords(checkpoint, recordBytes) >= 3; }));
    ASSERT_EQ(::kill(static_cast<pid_t>(run.pid()), SIGTERM), 0);
    ASSERT_TRUE(waitFor([&] { return run.finished(); }));
    ASSERT_EQ(run.exitCode(), 130) << readFile(dir.path() / "bg_stderr.txt");
    const std::string err = readFile(dir.path() / "bg_stderr.txt");
    EXPECT_TRUE(contains(err, "--resume")) << err;
    const size_t kept = checkpointRecords(checkpoint, recordBytes);
    EXPECT_GE(kept, 3u);
    EXPECT_LT(kept, 24u) << "the run finished before it could be interrupted";
    // The complete planes were written and open in the reader.
    const auto partial = optics::readTiffStack(dir.path() / "cut.expected.ome.tif", true);
    EXPECT_GE(partial.pages, 3);
    const auto full = optics::readTiffStack(dir.path() / "full.expected.ome.tif", true);
    ASSERT_EQ(full.pages, 24);
    EXPECT_TRUE(std::equal(partial.pixels.begin(), partial.pixels.end(), full.pixels.begin()));

    const auto resumed = runCli(dir, args("cut.ome.tif", true), 600);
    ASSERT_EQ(resumed.exitCode, 0) << resumed.err;
    EXPECT_TRUE(contains(resumed.err, "resuming")) << resumed.err;
    for (const char* suffix : {".ome.tif", ".expected.ome.tif", ".stderr.ome.tif"}) {
        const auto a = optics::readTiffStack(dir.path() / (std::string("cut") + suffix), true);
        const auto b = optics::readTiffStack(dir.path() / (std::string("full") + suffix), true);
        EXPECT_EQ(a.pages, 24) << suffix;
        EXPECT_EQ(a.pixels, b.pixels) << suffix;
    }
    EXPECT_FALSE(fs::exists(checkpoint)) << "a finished run removes its checkpoint";

    // A checkpoint from other options is refused.
    ASSERT_EQ(runCli(dir, {"acquire", scene.string(), "-o", (dir.path() / "x.ome.tif").string(), "--planes", "2", "--spp", "1"}).exitCode, 0);
    std::ofstream(dir.path() / "x.checkpoint") << "fluorosim acquire checkpoint 1\n{\"seed\":1}\n";
    const auto mismatch = runCli(dir, {"acquire", scene.string(), "-o", (dir.path() / "x.ome.tif").string(), "--planes", "2", "--spp", "1", "--resume"});
    EXPECT_EQ(mismatch.exitCode, 2);
    expectOneLineError(mismatch, {"x.checkpoint", "another scene, seed or options"});
}

}  // namespace
}  // namespace fluorosim
