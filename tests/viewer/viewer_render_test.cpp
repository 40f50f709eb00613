// The viewer rendering a scene it builds itself (two dye blobs, a microscope), under xvfb-run:
// frame sizes, channel colours at the blobs' projected centres, toggles, picks at known voxels,
// recorded key presses and drags, movies, and regression images against stored baselines.
#include <gtest/gtest.h>

#include <cstdlib>

#include "io/image_io.h"
#include "viewer/image_compare.h"
#include "viewer/key_bindings.h"
#include "viewer_fixture.h"

namespace fluorosim::testing {
namespace {

using viewer::Viewer;
using viewer::ViewPreset;

// World µm of voxel (i, j, k) of the test grid.
Vec3 voxelUm(const std::array<int, 3>& v) { return Vec3(v[0], v[1], v[2]) * kVoxelUm; }

std::array<int, 2> displayPixel(Viewer& v, ViewPreset view, const Vec3& worldUm) {
    const auto p = v.displayPosition(view, worldUm);
    EXPECT_TRUE(p.has_value());
    return p ? std::array<int, 2>{static_cast<int>(std::lround((*p)[0])), static_cast<int>(std::lround((*p)[1]))} : std::array<int, 2>{0, 0};
}

bool isGreen(const std::array<uint8_t, 3>& c) { return c[1] > 150 && c[0] < 60 && c[2] < 60; }
bool isMagenta(const std::array<uint8_t, 3>& c) { return c[0] > 150 && c[2] > 150 && c[1] < 60; }
bool isDark(const std::array<uint8_t, 3>& c) { return c[0] < 40 && c[1] < 40 && c[2] < 40; }
std::string rgbText(const std::array<uint8_t, 3>& c) {
    return "(" + std::to_string(c[0]) + ", " + std::to_string(c[1]) + ", " + std::to_string(c[2]) + ")";
}

// The 3D view from the top, without the microscope drawn over the blobs.
viewer::ViewerOptions topView(const ViewerScene& scene) {
    viewer::ViewerOptions o = scene.options();
    o.view = ViewPreset::Top;
    o.showMicroscope = false;
    return o;
}

TEST(ViewerRender, FrameHasTheRequestedSize) {
    TempDir dir;
    ViewerScene scene(dir);
    Viewer v(scene.options(320, 240));
    v.render();
    const viewer::FrameImage f = v.capture();
    EXPECT_EQ(f.width, 320);
    EXPECT_EQ(f.height, 240);
    v.saveScreenshot(dir.path() / "shot.png");
    EXPECT_EQ(pngSize(dir.path() / "shot.png"), (std::array<int, 2>{320, 240}));
}

TEST(ViewerRender, BlobCentresShowTheirChannelColours) {
    TempDir dir;
    ViewerScene scene(dir);
    for (const viewer::MapperChoice mapper : {viewer::MapperChoice::Cpu, viewer::MapperChoice::Gpu}) {
        viewer::ViewerOptions o = topView(scene);
        o.mapper = mapper;
        Viewer v(o);
        v.render();
        const viewer::FrameImage f = v.capture();
        const auto g = displayPixel(v, ViewPreset::ThreeD, voxelUm(kGreenBlob.centre));
        const auto m = displayPixel(v, ViewPreset::ThreeD, voxelUm(kMagentaBlob.centre));
        EXPECT_TRUE(isGreen(f.at(g[0], g[1]))) << v.mapperName() << ": AF488 blob centre is " << rgbText(f.at(g[0], g[1]));
        EXPECT_TRUE(isMagenta(f.at(m[0], m[1]))) << v.mapperName() << ": AF594 blob centre is " << rgbText(f.at(m[0], m[1]));
        // Between the blobs, far from both (8 sigma), the projection is black.
        const auto mid = displayPixel(v, ViewPreset::ThreeD, 0.5 * (voxelUm(kGreenBlob.centre) + voxelUm(kMagentaBlob.centre)));
        EXPECT_TRUE(isDark(f.at(mid[0], mid[1]))) << v.mapperName() << ": between the blobs " << rgbText(f.at(mid[0], mid[1]));
    }
}

TEST(ViewerRender, HidingAChannelRemovesItsBlobOnly) {
    TempDir dir;
    ViewerScene scene(dir);
    Viewer v(topView(scene));
    v.setChannelVisible(0, false);
    v.render();
    const viewer::FrameImage f = v.capture();
    const auto g = displayPixel(v, ViewPreset::ThreeD, voxelUm(kGreenBlob.centre));
    const auto m = displayPixel(v, ViewPreset::ThreeD, voxelUm(kMagentaBlob.centre));
    EXPECT_TRUE(isDark(f.at(g[0], g[1]))) << "hidden AF488 blob: " << rgbText(f.at(g[0], g[1]));
    EXPECT_TRUE(isMagenta(f.at(m[0], m[1]))) << "AF594 blob: " << rgbText(f.at(m[0], m[1]));
    v.setChannelVisible(0, true);
    v.render();
    EXPECT_TRUE(isGreen(v.capture().at(g[0], g[1])));
}

TEST(ViewerRender, ChannelKeysToggleAndSolo) {
    TempDir dir;
    ViewerScene scene(dir);
    Viewer v(topView(scene));
    v.render();
    const auto g = displayPixel(v, ViewPreset::ThreeD, voxelUm(kGreenBlob.centre));
    const auto m = displayPixel(v, ViewPreset::ThreeD, voxelUm(kMagentaBlob.centre));
    v.playEvents("# StreamVersion 1.1\n" + keyPress("1"));
    EXPECT_FALSE(v.channels()[0].visible);
    EXPECT_TRUE(v.channels()[1].visible);
    EXPECT_EQ(v.activeChannel(), 0);
    EXPECT_TRUE(isDark(v.capture().at(g[0], g[1])));
    v.playEvents("# StreamVersion 1.1\n" + keyPress("0"));
    EXPECT_TRUE(v.channels()[0].visible);
    // Shift+2 (the keyboard sends "at") shows channel 2 alone.
    v.playEvents("# StreamVersion 1.1\n" + keyPress("at", 10, 10, true));
    EXPECT_FALSE(v.channels()[0].visible);
    EXPECT_TRUE(v.channels()[1].visible);
    EXPECT_EQ(v.activeChannel(), 1);
    const viewer::FrameImage f = v.capture();
    EXPECT_TRUE(isDark(f.at(g[0], g[1])));
    EXPECT_TRUE(isMagenta(f.at(m[0], m[1])));
}

TEST(ViewerRender, PickInTheXySliceReturnsTheVoxelAndItsValues) {
    TempDir dir;
    ViewerScene scene(dir);
    viewer::ViewerOptions o = scene.options();
    o.view = ViewPreset::SliceXy;
    Viewer v(o);
    ASSERT_EQ(v.planeCount(), kPlanes);
    EXPECT_EQ(v.plane(), 2);  // the focal plane, z = 12 µm, the blobs' plane
    v.render();
    for (const std::array<int, 3> voxel : {kGreenBlob.centre, std::array<int, 3>{14, 21, 12}, std::array<int, 3>{27, 18, 12}}) {
        const auto p = displayPixel(v, ViewPreset::SliceXy, voxelUm(voxel));
        const viewer::Readout r = v.pick(p[0], p[1]);
        ASSERT_TRUE(r.valid);
        EXPECT_EQ(r.view, "xy");
        EXPECT_EQ(r.voxel, voxel);
        EXPECT_TRUE(r.insideGrid);
        ASSERT_EQ(r.values.size(), 2u);
        EXPECT_EQ(r.names, (std::vector<std::string>{"AF488", "AF594"}));
        EXPECT_EQ(r.units, (std::vector<std::string>{"uM", "uM"}));
        // The grid stores floats of the blobs (values below 1e-3 left out).
        const auto stored = [&](const Blob& b) {
            const double x = b.at(voxel[0], voxel[1], voxel[2]);
            return x > 1e-3 ? double(static_cast<float>(x)) : 0.0;
        };
        EXPECT_DOUBLE_EQ(r.values[0], stored(kGreenBlob));
        EXPECT_DOUBLE_EQ(r.values[1], stored(kMagentaBlob));
        EXPECT_NEAR(r.positionUm.z, 12.0, 1e-9);
    }
}

TEST(ViewerRender, PickInTheThreeDViewFindsTheBlob) {
    TempDir dir;
    ViewerScene scene(dir);
    Viewer v(topView(scene));
    v.render();
    const auto m = displayPixel(v, ViewPreset::ThreeD, voxelUm(kMagentaBlob.centre));
    const viewer::Readout r = v.pick(m[0], m[1]);
    ASSERT_TRUE(r.valid);
    EXPECT_EQ(r.view, "3d");
    // The ray from the top meets the blob where its opacity first passes 0.1: above the centre, within
    // three standard deviations, on AF594 voxels.
    EXPECT_EQ(r.voxel[0], kMagentaBlob.centre[0]);
    EXPECT_EQ(r.voxel[1], kMagentaBlob.centre[1]);
    EXPECT_GE(r.voxel[2], kMagentaBlob.centre[2]);
    EXPECT_LE(r.voxel[2], kMagentaBlob.centre[2] + 3 * kMagentaBlob.sigmaVoxels);
    EXPECT_GT(r.values[1], 0);
    EXPECT_EQ(r.values[0], 0);
}

TEST(ViewerRender, RecordedKeysMoveZ) {
    TempDir dir;
    ViewerScene scene(dir);
    Viewer v(scene.options());
    v.render();
    ASSERT_EQ(v.plane(), 2);
    v.playEvents("# StreamVersion 1.1\n" + keyPress("Up"));
    EXPECT_EQ(v.plane(), 3);
    v.playEvents("# StreamVersion 1.1\n" + keyPress("Down") + keyPress("Down") + keyPress("Left"));
    EXPECT_EQ(v.plane(), 0);
    v.playEvents("# StreamVersion 1.1\n" + keyPress("Down"));
    EXPECT_EQ(v.plane(), 0);  // clamped
    v.playEvents("# StreamVersion 1.1\n" + keyPress("End"));
    EXPECT_EQ(v.plane(), kPlanes - 1);
    v.playEvents("# StreamVersion 1.1\n" + keyPress("Home") + keyPress("Prior"));
    EXPECT_EQ(v.plane(), kPlanes - 1);  // 10 planes up, clamped
}

TEST(ViewerRender, WheelInTheXySliceMovesZ) {
    TempDir dir;
    ViewerScene scene(dir);
    viewer::ViewerOptions o = scene.options();
    o.view = ViewPreset::SliceXy;
    Viewer v(o);
    v.render();
    v.playEvents("# StreamVersion 1.1\n" + mouseEvent("MouseMoveEvent", 200, 150) + mouseEvent("MouseWheelForwardEvent", 200, 150));
    EXPECT_EQ(v.plane(), 3);
    v.playEvents("# StreamVersion 1.1\n" + mouseEvent("MouseWheelBackwardEvent", 200, 150) + mouseEvent("MouseWheelBackwardEvent", 200, 150));
    EXPECT_EQ(v.plane(), 1);
}

TEST(ViewerRender, RightDragSetsWindowAndLevelOfTheActiveChannel) {
    TempDir dir;
    ViewerScene scene(dir);
    Viewer v(scene.options());
    v.render();
    v.playEvents("# StreamVersion 1.1\n" + keyPress("Tab"));  // channel 2 (AF594) becomes active
    ASSERT_EQ(v.activeChannel(), 1);
    const viewer::ChannelState before = v.channels()[1], other = v.channels()[0];
    const double width0 = before.high - before.low, level0 = 0.5 * (before.high + before.low);
    // 100 pixels to the right: the window widens by a quarter (400 pixels span it once); the level stays.
    v.playEvents("# StreamVersion 1.1\n" + mouseEvent("RightButtonPressEvent", 150, 150) + mouseEvent("MouseMoveEvent", 200, 150) +
                 mouseEvent("MouseMoveEvent", 250, 150) + mouseEvent("RightButtonReleaseEvent", 250, 150));
    const viewer::ChannelState wider = v.channels()[1];
    EXPECT_NEAR(wider.high - wider.low, 1.25 * width0, 1e-9 * width0);
    EXPECT_NEAR(0.5 * (wider.high + wider.low), level0, 1e-9 * width0);
    // 80 pixels up: the level rises by a fifth of the window; the width stays.
    const double width1 = wider.high - wider.low;
    v.playEvents("# StreamVersion 1.1\n" + mouseEvent("RightButtonPressEvent", 150, 150) + mouseEvent("MouseMoveEvent", 150, 230) +
                 mouseEvent("RightButtonReleaseEvent", 150, 230));
    const viewer::ChannelState higher = v.channels()[1];
    EXPECT_NEAR(higher.high - higher.low, width1, 1e-9 * width1);
    EXPECT_NEAR(0.5 * (higher.high + higher.low), level0 + 0.2 * width1, 1e-9 * width1);
    // The other channel is untouched.
    EXPECT_EQ(v.channels()[0].low, other.low);
    EXPECT_EQ(v.channels()[0].high, other.high);
}

TEST(ViewerRender, NarrowerWindowBrightensTheSlice) {
    TempDir dir;
    ViewerScene scene(dir);
    viewer::ViewerOptions o = scene.options();
    o.view = ViewPreset::SliceXy;
    Viewer v(o);
    v.render();
    // A voxel at half the peak: its green grows when the window closes to [0, 0.6 peak].
    const std::array<int, 3> voxel{12, 22, 12};  // 10 exp(-4/8) = 6.07 µM
    const auto p = displayPixel(v, ViewPreset::SliceXy, voxelUm(voxel));
    v.setWindow(0, 0, kGreenBlob.peakUm);
    v.render();
    const int before = v.capture().at(p[0], p[1])[1];
    EXPECT_NEAR(before, 255 * kGreenBlob.at(12, 22, 12) / kGreenBlob.peakUm, 3);
    v.setWindow(0, 0, 0.6 * kGreenBlob.peakUm);
    v.render();
    EXPECT_GE(v.capture().at(p[0], p[1])[1], 250);
}

TEST(ViewerRender, BlendKeySwitchesBetweenMipAndComposite) {
    TempDir dir;
    ViewerScene scene(dir);
    Viewer v(scene.options());
    EXPECT_EQ(v.blendMode(), viewer::BlendMode::Mip);
    v.playEvents("# StreamVersion 1.1\n" + keyPress("m"));
    EXPECT_EQ(v.blendMode(), viewer::BlendMode::Composite);
    v.playEvents("# StreamVersion 1.1\n" + keyPress("m"));
    EXPECT_EQ(v.blendMode(), viewer::BlendMode::Mip);
}

TEST(ViewerRender, ZSweepWritesOneFramePerPlaneAndOrbitAnOggFile) {
    TempDir dir;
    ViewerScene scene(dir);
    Viewer v(scene.options(320, 240));
    v.writeMovie(dir.path() / "sweep", viewer::MovieKind::ZSweep, 0);
    for (int k = 0; k < kPlanes; ++k) {
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04d.png", k);
        EXPECT_EQ(pngSize(dir.path() / "sweep" / name), (std::array<int, 2>{320, 240})) << name;
    }
    EXPECT_FALSE(fs::exists(dir.path() / "sweep" / "frame_0005.png"));
    EXPECT_EQ(v.plane(), 2);  // back where it was
    v.writeMovie(dir.path() / "orbit.ogv", viewer::MovieKind::Orbit, 6);
    EXPECT_EQ(readFile(dir.path() / "orbit.ogv").substr(0, 4), "OggS");
}

TEST(ViewerRender, ComparePickReadsTheStackInCameraOrientation) {
    TempDir dir;
    ViewerScene scene(dir);
    viewer::ViewerOptions o = scene.options(480, 360);
    // Every pixel of the stack encodes its own column, row (from the top) and plane.
    o.stack = scene.writeStack("code.expected.ome.tif", kDetectorPixels, kDetectorPixels, kPlanes, kPixelUm, {"AF488"},
                               [](int, int z, int x, int y) { return 10000 * z + 100 * y + x; });
    o.view = ViewPreset::Compare;
    Viewer v(o);
    v.render();
    for (const auto& [col, row] : {std::pair{3, 5}, std::pair{60, 2}, std::pair{31, 62}}) {
        // Pixel (col, row) is drawn at ((col + 0.5) p, (63 - row + 0.5) p) in the panel's µm.
        const auto p = displayPixel(v, ViewPreset::Compare, Vec3((col + 0.5) * kPixelUm, (63 - row + 0.5) * kPixelUm, 0));
        const viewer::Readout r = v.pick(p[0], p[1]);
        ASSERT_TRUE(r.valid);
        EXPECT_EQ(r.view, "compare");
        EXPECT_EQ(r.pixel, (std::array<int, 2>{col, row}));
        ASSERT_GE(r.values.size(), 3u);
        EXPECT_EQ(r.names[0], "AF488 simulated");
        EXPECT_EQ(r.values[0], 10000 * 2 + 100 * row + col);
        // The truth there is the AF488 blob at the pixel's centre (trilinear): compare with the Gaussian.
        const double x = kFocusUm.x + (col + 0.5 - 32) * kPixelUm, y = kFocusUm.y + (32 - row - 0.5) * kPixelUm;
        EXPECT_NEAR(r.values[1], kGreenBlob.at(x, y, kFocusUm.z), 0.05 * kGreenBlob.peakUm);
    }
}

TEST(ViewerRender, ChannelSelectionAppliesToTheStackToo) {
    TempDir dir;
    ViewerScene scene(dir);
    scene.scene()["microscope"]["channels"].push_back(json{{"name", "AF594"}, {"emission_filter", "semrock_FF01-609-54"}, {"lights", {0}}});
    scene.write();
    viewer::ViewerOptions o = scene.options(480, 360);
    // AF488: a flat 50 everywhere (it would paint the whole panel green); AF594: the magenta blob.
    o.stack = scene.writeStack("two.expected.ome.tif", kDetectorPixels, kDetectorPixels, kPlanes, kPixelUm, {"AF488", "AF594"},
                               [](int c, int z, int x, int y) {
                                   const double px = kFocusUm.x + (x + 0.5 - 32) * kPixelUm, py = kFocusUm.y + (32 - y - 0.5) * kPixelUm;
                                   return c == 0 ? 50.0 : 100 * kMagentaBlob.at(px, py, kFocusUm.z + kStepUm * (z - 2));
                               });
    o.view = ViewPreset::Compare;
    o.channels = {"AF594"};
    Viewer v(o);
    ASSERT_EQ(v.channels().size(), 2u);
    EXPECT_FALSE(v.channels()[0].visible);
    EXPECT_TRUE(v.channels()[1].visible);
    EXPECT_EQ(v.activeChannel(), 1);
    v.render();
    const viewer::FrameImage f = v.capture();
    // The blob's pixel: column (28 - 20) / p + 31.5, row 31.5 - (20 - 18) / p, drawn at ((col + 0.5) p, (63 - row + 0.5) p).
    const double col = (kMagentaBlob.centre[0] - kFocusUm.x) / kPixelUm + 31.5, row = 31.5 - (kMagentaBlob.centre[1] - kFocusUm.y) / kPixelUm;
    const auto blob = displayPixel(v, ViewPreset::Compare, Vec3((col + 0.5) * kPixelUm, (63 - row + 0.5) * kPixelUm, 0));
    const auto corner = displayPixel(v, ViewPreset::Compare, Vec3(2.5 * kPixelUm, 2.5 * kPixelUm, 0));
    EXPECT_TRUE(isMagenta(f.at(blob[0], blob[1]))) << rgbText(f.at(blob[0], blob[1]));
    EXPECT_TRUE(isDark(f.at(corner[0], corner[1]))) << "hidden AF488 shows: " << rgbText(f.at(corner[0], corner[1]));
}

TEST(ViewerRender, ExrCompositeAndBands) {
    TempDir dir;
    // Left half: only 450 nm (and blue in RGB); right half: only 650 nm (red); 550 nm dim everywhere.
    ExrImage img;
    img.width = 32;
    img.height = 16;
    img.rgb.assign(32 * 16 * 3, 0.f);
    std::vector<float> bands(3 * 32 * 16, 0.f);
    for (int y = 0; y < 16; ++y)
        for (int x = 0; x < 32; ++x) {
            const size_t i = size_t(y) * 32 + size_t(x);
            img.rgb[i * 3 + (x < 16 ? 2 : 0)] = 0.5f;
            bands[(x < 16 ? 0 : 2) * 512 + i] = 1.f;
            bands[512 + i] = 0.3f;
        }
    img.spectral.push_back({"", {450, 550, 650}, bands});
    writeExr((dir.path() / "img.exr").string(), img);
    viewer::ViewerOptions o;
    o.exr = dir.path() / "img.exr";
    o.offscreen = true;
    o.width = 400;
    o.height = 300;
    Viewer v(o);
    EXPECT_EQ(v.view(), ViewPreset::Exr);
    v.render();
    const auto left = displayPixel(v, ViewPreset::Exr, Vec3(4.5, 8.5, 0)), right = displayPixel(v, ViewPreset::Exr, Vec3(27.5, 8.5, 0));
    viewer::FrameImage f = v.capture();
    EXPECT_EQ(f.at(left[0], left[1]), (std::array<uint8_t, 3>{0, 0, 255})) << rgbText(f.at(left[0], left[1]));
    EXPECT_EQ(f.at(right[0], right[1]), (std::array<uint8_t, 3>{255, 0, 0})) << rgbText(f.at(right[0], right[1]));
    // The band keys: 450 nm lights the left half only, in violet-blue.
    v.playEvents("# StreamVersion 1.1\n" + keyPress("Right"));
    f = v.capture();
    EXPECT_EQ(f.at(left[0], left[1])[2], 255) << rgbText(f.at(left[0], left[1]));
    EXPECT_LT(f.at(left[0], left[1])[1], 60) << rgbText(f.at(left[0], left[1]));
    EXPECT_TRUE(isDark(f.at(right[0], right[1]))) << rgbText(f.at(right[0], right[1]));
    const viewer::Readout r = v.pick(left[0], left[1]);
    ASSERT_TRUE(r.valid);
    EXPECT_EQ(r.pixel, (std::array<int, 2>{4, 16 - 1 - 8}));
    EXPECT_EQ(r.names.back(), "450.0 nm");
    EXPECT_EQ(r.values.back(), 1.0);
}

TEST(ViewerRender, HelpListsEveryBinding) {
    TempDir dir;
    ViewerScene scene(dir);
    Viewer v(scene.options());
    const std::string help = v.helpText();
    const std::string docs = readFile(fs::path(FLUOROSIM_SOURCE_DIR) / "docs" / "viewer.md");
    for (const viewer::KeyBinding& b : viewer::keyBindings()) {
        EXPECT_TRUE(contains(help, b.keys)) << b.keys;
        EXPECT_TRUE(contains(help, b.action)) << b.action;
        EXPECT_TRUE(contains(docs, "| " + std::string(b.keys) + " | " + b.action + " |")) << "docs/viewer.md lacks the row for " << b.keys;
    }
}

// Regression images: the frame against tests/viewer/baselines/NAME.png with VTK's measure and
// threshold. FLUOROSIM_UPDATE_BASELINES=1 writes the baseline instead (and skips).
void expectMatchesBaseline(Viewer& v, const std::string& name) {
    v.render();
    const viewer::FrameImage frame = v.capture();
    const fs::path baseline = fs::path(FLUOROSIM_VIEWER_BASELINES) / (name + ".png");
    const char* update = std::getenv("FLUOROSIM_UPDATE_BASELINES");
    if (update && std::string(update) == "1") {
        viewer::writePng(frame, baseline);
        GTEST_SKIP() << "wrote " << baseline;
    }
    const fs::path actual = fs::temp_directory_path() / ("fluorosim_viewer_" + name + ".png");
    viewer::writePng(frame, actual);
    ASSERT_TRUE(fs::exists(baseline)) << "no baseline " << baseline << "; this run's image is " << actual;
    const double error = viewer::imageDifference(frame, baseline);
    EXPECT_LE(error, viewer::kVtkRegressionThreshold) << name << ": thresholded error " << error << "; this run's image is " << actual;
}

TEST(ViewerBaseline, Overview) {
    TempDir dir;
    ViewerScene scene(dir);
    Viewer v(scene.options(480, 360));
    expectMatchesBaseline(v, "overview");
}

TEST(ViewerBaseline, CompareView) {
    TempDir dir;
    ViewerScene scene(dir);
    viewer::ViewerOptions o = scene.options(480, 360);
    // A stack that is the truth, scaled, plus a bright square the truth does not have.
    o.stack = scene.writeStack("stack.expected.ome.tif", kDetectorPixels, kDetectorPixels, kPlanes, kPixelUm, {"AF488"},
                               [](int, int z, int x, int y) {
                                   const double square = x >= 40 && x < 48 && y >= 40 && y < 48 ? 300.0 : 0.0;
                                   const double px = kFocusUm.x + (x + 0.5 - 32) * kPixelUm, py = kFocusUm.y + (32 - y - 0.5) * kPixelUm;
                                   return 100 * kGreenBlob.at(px, py, kFocusUm.z + kStepUm * (z - 2)) + 5 + square;
                               });
    o.view = ViewPreset::Compare;
    Viewer v(o);
    expectMatchesBaseline(v, "compare");
}

TEST(ViewerBaseline, ThreeDWithMicroscope) {
    TempDir dir;
    ViewerScene scene(dir);
    viewer::ViewerOptions o = scene.options(480, 360);
    o.view = ViewPreset::ThreeD;
    Viewer v(o);
    expectMatchesBaseline(v, "threed_microscope");
}

}  // namespace
}  // namespace fluorosim::testing
