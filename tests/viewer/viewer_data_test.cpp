// What the viewer computes before VTK sees it: the display volume, voxel readouts, the microscope's
// geometry, OME-XML, the ground truth on the detector grid with its fit, SWC placement, spectral EXR.
#include <gtest/gtest.h>

#include "optics/scene_files.h"
#include "optics/voxelize_request.h"
#include "io/image_io.h"
#include "support/fluorescent_scenes.h"
#include "viewer/microscope_overlay.h"
#include "viewer/spectral_image.h"
#include "viewer/specimen.h"
#include "viewer/stack_comparison.h"
#include "viewer_fixture.h"

namespace fluorosim::testing {
namespace {

struct Loaded {
    Scene scene;
    optics::Microscope microscope;
    viewer::Specimen specimen;
};

Loaded load(const ViewerScene& s, viewer::SpecimenOptions options = {{}, false}) {
    Scene scene = optics::loadSceneFile(s.path(), database());
    optics::Microscope m = optics::Microscope::fromScene(scene, database());
    viewer::Specimen sp = viewer::loadSpecimen(scene, s.path(), options);
    return {std::move(scene), std::move(m), std::move(sp)};
}

double storedValue(const Blob& b, int i, int j, int k) {
    const double x = b.at(i, j, k);
    return x > 1e-3 ? double(static_cast<float>(x)) : 0.0;
}

TEST(ViewerData, SpecimenHasTheScenesDyesAndGrids) {
    TempDir dir;
    ViewerScene s(dir);
    const Loaded l = load(s);
    ASSERT_EQ(l.specimen.channels.size(), 2u);
    EXPECT_EQ(l.specimen.channels[0].name, "AF488");
    EXPECT_EQ(l.specimen.channels[1].name, "AF594");
    EXPECT_EQ(l.specimen.channels[0].units, "uM");
    EXPECT_EQ(l.specimen.gridMedium, "tissue");
    // Voxel (i, j, k) sits at (i, j, k) µm.
    const Vec3 w = l.specimen.channels[0].worldUmFromIndex.apply(Vec3(3, 4, 5));
    EXPECT_NEAR(w.x, 3, 1e-9);
    EXPECT_NEAR(w.y, 4, 1e-9);
    EXPECT_NEAR(w.z, 5, 1e-9);
}

TEST(ViewerData, ProbeReturnsTheNearestVoxelsValues) {
    TempDir dir;
    ViewerScene s(dir);
    const Loaded l = load(s);
    const viewer::VoxelProbe p = viewer::probeVoxel(l.specimen, Vec3(13.6, 20.2, 11.7));
    EXPECT_EQ(p.index, (std::array<int, 3>{14, 20, 12}));
    EXPECT_TRUE(p.insideGrid);
    EXPECT_DOUBLE_EQ(p.values[0], storedValue(kGreenBlob, 14, 20, 12));
    EXPECT_DOUBLE_EQ(p.values[1], storedValue(kMagentaBlob, 14, 20, 12));
    const viewer::VoxelProbe outside = viewer::probeVoxel(l.specimen, Vec3(-30, 0, 0));
    EXPECT_FALSE(outside.insideGrid);
    EXPECT_EQ(outside.values[0], 0.0);
}

TEST(ViewerData, DisplayVolumeHoldsTheMaximumOfEachBlock) {
    TempDir dir;
    ViewerScene s(dir);
    const Loaded l = load(s);
    viewer::DisplayVolumeOptions o;
    o.maxVoxels = 8000;  // 40 x 40 x 24 = 38400 voxels; at stride 2, 20 x 20 x 12 = 4800 fit
    const auto v = viewer::makeDisplayVolume(l.specimen, o);
    ASSERT_TRUE(v);
    ASSERT_EQ(v->stride, 2);
    // The grids hold values (above 1e-3 µM) in whole 8³ leaves: x 0..39, y 8..31, z 0..23.
    EXPECT_EQ(v->indexLo, (std::array<int, 3>{0, 8, 0}));
    EXPECT_EQ(v->dims, (std::array<int, 3>{20, 12, 12}));
    EXPECT_EQ(v->channels, (std::vector<int>{0, 1}));
    // Display voxel (i, j, k) covers voxels indexLo + 2 (i, j, k) + (0 or 1) and sits at their centre.
    const Vec3 c = v->centreUm(6, 6, 6);
    EXPECT_NEAR(c.x, 12.5, 1e-9);
    EXPECT_NEAR(c.y, 20.5, 1e-9);
    EXPECT_NEAR(c.z, 12.5, 1e-9);
    EXPECT_EQ(v->spacingUm, (std::array<double, 3>{2, 2, 2}));
    for (const auto& [blob, component] : {std::pair{kGreenBlob, 0}, std::pair{kMagentaBlob, 1}})
        for (int k = 0; k < v->dims[2]; ++k)
            for (int j = 0; j < v->dims[1]; ++j)
                for (int i = 0; i < v->dims[0]; ++i) {
                    double expected = 0;
                    for (int dz = 0; dz < 2; ++dz)
                        for (int dy = 0; dy < 2; ++dy)
                            for (int dx = 0; dx < 2; ++dx)
                                expected = std::max(expected, storedValue(blob, 2 * i + dx, 8 + 2 * j + dy, 2 * k + dz));
                    // Quantised to 65535 steps of the channel's maximum.
                    ASSERT_NEAR(v->value(i, j, k, component), expected, 0.51 * v->unitPerCount[size_t(component)])
                        << "display voxel " << i << ", " << j << ", " << k;
                }
}

TEST(ViewerData, RegionCropsTheDisplayVolumeAtFullResolution) {
    TempDir dir;
    ViewerScene s(dir);
    const Loaded l = load(s);
    viewer::DisplayVolumeOptions o;
    o.regionUm = std::array<Vec3, 2>{Vec3(10.2, 15, 9), Vec3(20.7, 25, 14)};
    const auto v = viewer::makeDisplayVolume(l.specimen, o);
    ASSERT_TRUE(v);
    EXPECT_EQ(v->stride, 1);
    EXPECT_EQ(v->indexLo, (std::array<int, 3>{10, 15, 9}));
    EXPECT_EQ(v->dims, (std::array<int, 3>{12, 11, 6}));  // voxels 10..21, 15..25, 9..14
    EXPECT_NEAR(v->value(2, 5, 3, 0), storedValue(kGreenBlob, 12, 20, 12), 0.51 * v->unitPerCount[0]);
}

TEST(ViewerData, FieldOfViewFollowsTheDetectorAndThePlane) {
    TempDir dir;
    ViewerScene s(dir);
    const Loaded l = load(s);
    const viewer::MicroscopeOverlay o(l.scene, l.microscope, kPlanes, kStepUm);
    EXPECT_NEAR(o.offsetUm(0), -4, 1e-9);
    EXPECT_NEAR(o.offsetUm(4), 4, 1e-9);
    const viewer::FieldOfView f = o.fieldOfView(4);
    EXPECT_NEAR(f.pixelUm, kPixelUm, 1e-12);
    EXPECT_NEAR(f.centreUm.z, kFocusUm.z + 4, 1e-9);
    // Columns along +x, rows down -y (up is +y), centred on the focus.
    const Vec3 p = f.pixelCentreUm(0, 0);
    EXPECT_NEAR(p.x, kFocusUm.x - 31.5 * kPixelUm, 1e-9);
    EXPECT_NEAR(p.y, kFocusUm.y + 31.5 * kPixelUm, 1e-9);
    EXPECT_NEAR(length(f.cornersUm[1] - f.cornersUm[0]), 64 * kPixelUm, 1e-9);
    EXPECT_NEAR(f.cornersUm[0].x, kFocusUm.x - 32 * kPixelUm, 1e-9);
    EXPECT_NEAR(f.cornersUm[0].y, kFocusUm.y + 32 * kPixelUm, 1e-9);
    const viewer::CollectionCone c = o.cone(2);
    EXPECT_NEAR(c.halfAngleRad, std::asin(0.8 / 1.33), 1e-12);
    EXPECT_NEAR(c.lengthUm, 50, 1e-9);
}

TEST(ViewerData, SheetMovesWithThePlaneAndWidensAsAGaussianBeam) {
    TempDir dir;
    ViewerScene s(dir);
    const Loaded l = load(s);
    const viewer::MicroscopeOverlay o(l.scene, l.microscope, kPlanes, kStepUm);
    const auto sheets = o.sheets(3);
    ASSERT_EQ(sheets.size(), 1u);
    const viewer::SheetEnvelope& e = sheets[0];
    EXPECT_NEAR(e.centreUm.z, kFocusUm.z + 2, 1e-9);
    EXPECT_NEAR(e.centreUm.x, kFocusUm.x, 1e-9);
    EXPECT_NEAR(e.waistUm, 2, 1e-12);
    const double zR = kPi * 2.0 * 2.0 * 1.33 / 0.488;  // π w0² n / λ, µm
    EXPECT_NEAR(e.rayleighUm, zR, 1e-9 * zR);
    EXPECT_NEAR(e.halfWidthUm(zR), 2 * std::sqrt(2.0), 1e-12);
    EXPECT_NEAR(e.heightUm, 50, 1e-9);
}

TEST(ViewerData, OmeXmlRoundTrip) {
    optics::StackMetadata meta;
    meta.pixelSizeUm = 0.40625;
    meta.zStepUm = 2;
    meta.channels = {{"A&B <1>", 488, 525}, {"AF594", 561, 609}};
    const std::string xml = optics::omeXml(64, 32, 5, 2, "float", meta);
    const viewer::OmeStackInfo info = viewer::parseOmeXml(xml, "x.ome.tif");
    EXPECT_EQ(info.width, 64);
    EXPECT_EQ(info.height, 32);
    EXPECT_EQ(info.planes, 5);
    EXPECT_EQ(info.channels, 2);
    EXPECT_DOUBLE_EQ(info.pixelSizeUm, 0.40625);
    EXPECT_DOUBLE_EQ(info.zStepUm, 2);
    EXPECT_EQ(info.channelNames, (std::vector<std::string>{"A&B <1>", "AF594"}));
    EXPECT_THROW(viewer::parseOmeXml("<x/>", "x.ome.tif"), ConfigError);
}

TEST(ViewerData, GroundTruthOnTheDetectorGridFitsAScaledStack) {
    TempDir dir;
    ViewerScene s(dir);
    const Loaded l = load(s);
    // The stack is 100 × the AF488 concentration at each pixel centre plus 5, computed here from the
    // blob itself: pixel (x, y) of plane z sits at the focus + ((x + 0.5 - 32) p, (32 - y - 0.5) p, 2 (z - 2)).
    auto truth = [](int z, int x, int y) {
        const double px = kFocusUm.x + (x + 0.5 - 32) * kPixelUm, py = kFocusUm.y + (32 - y - 0.5) * kPixelUm;
        return kGreenBlob.at(px, py, kFocusUm.z + kStepUm * (z - 2));
    };
    const fs::path stack = s.writeStack("a.expected.ome.tif", kDetectorPixels, kDetectorPixels, kPlanes, kPixelUm, {"AF488"},
                                        [&](int, int z, int x, int y) { return 100 * truth(z, x, y) + 5; });
    const viewer::StackComparison c = viewer::loadStackComparison(stack, l.scene, l.microscope, l.specimen);
    ASSERT_EQ(c.channels.size(), 1u);
    const viewer::ChannelComparison& cc = c.channels[0];
    EXPECT_FALSE(c.counts);
    EXPECT_EQ(cc.truthChannel, 0);
    // Trilinear interpolation of the voxels differs from the Gaussian itself by a few percent.
    EXPECT_NEAR(cc.fitScale, 100, 5);
    EXPECT_NEAR(cc.fitOffset, 5, 2);
    EXPECT_GT(cc.correlation, 0.995);
    EXPECT_LT(cc.residualRms, 0.03 * 100 * kGreenBlob.peakUm);
    // The truth's peak is at the pixel nearest the blob's centre, in the focal plane.
    const auto peak = std::max_element(cc.truth.begin(), cc.truth.end()) - cc.truth.begin();
    const int plane = static_cast<int>(peak / (64 * 64)), row = static_cast<int>(peak % (64 * 64) / 64), col = static_cast<int>(peak % 64);
    EXPECT_EQ(plane, 2);
    EXPECT_NEAR(kFocusUm.x + (col + 0.5 - 32) * kPixelUm, kGreenBlob.centre[0], kPixelUm);
    EXPECT_NEAR(kFocusUm.y + (32 - row - 0.5) * kPixelUm, kGreenBlob.centre[1], kPixelUm);
}

TEST(ViewerData, StackFindsItsSibling) {
    TempDir dir;
    ViewerScene s(dir);
    const Loaded l = load(s);
    auto flat = [](int, int, int, int) { return 1.0; };
    const fs::path counts = s.writeStack("b.ome.tif", 64, 64, 5, kPixelUm, {"AF488"}, flat);
    EXPECT_FALSE(viewer::loadStackComparison(counts, l.scene, l.microscope, l.specimen).sibling);
    const fs::path expected = s.writeStack("b.expected.ome.tif", 64, 64, 5, kPixelUm, {"AF488"}, flat);
    EXPECT_EQ(viewer::loadStackComparison(counts, l.scene, l.microscope, l.specimen).sibling, expected);
    EXPECT_EQ(viewer::loadStackComparison(expected, l.scene, l.microscope, l.specimen).sibling, counts);
}

TEST(ViewerData, SwcBesideTheVolumeIsPlacedLikeTheGrid) {
    TempDir dir;
    ViewerScene s(dir);
    // A soma of radius 3 µm on the AF594 blob and a dendrite along +x, in the voxelizer's µm.
    std::ofstream(dir.path() / "cell.swc") << "1 1 28 20 12 3 -1\n2 3 34 20 12 1 1\n3 3 38 20 12 0.5 2\n";
    const Loaded l = load(s, {{}, true});
    ASSERT_EQ(l.specimen.neurons.size(), 1u);
    const viewer::NeuronModel& n = l.specimen.neurons[0];
    EXPECT_EQ(n.channel, 1);
    ASSERT_FALSE(n.pieces.empty());
    EXPECT_TRUE(n.pieces[0].sphere);
    EXPECT_NEAR(n.pieces[0].aUm.x, 28, 1e-9);
    EXPECT_NEAR(n.pieces[0].aUm.z, 12, 1e-9);
    EXPECT_NEAR(n.pieces[0].raUm, 3, 1e-9);
    const MorphologyPiece& tip = n.pieces.back();
    EXPECT_NEAR(tip.aUm.x, 34, 1e-9);
    EXPECT_NEAR(tip.bUm.x, 38, 1e-9);
    EXPECT_NEAR(tip.rbUm, 0.5, 1e-9);
}

// A volume voxelized by fluorosim names its neurons: the viewer draws those, placed as they were
// voxelized, and not a stray SWC file in the same folder; its notes say what it drew.
TEST(ViewerData, TheVolumesOwnNeuronsAreDrawnWithTheirPlacement) {
    TempDir dir;
    ViewerScene s(dir);
    std::ofstream(dir.path() / "cell.swc") << "1 1 0 0 0 3 -1\n2 3 6 0 0 1 1\n";
    std::ofstream(dir.path() / "stray.swc") << "1 1 5 5 5 2 -1\n";
    optics::VoxelizeArgs a;
    a.swc = {(dir.path() / "cell.swc").string(), (dir.path() / "cell.swc").string()};
    a.voxel = "1um";
    a.dyes = {"AF488", "AF594"};
    a.concentrations = {"10uM"};
    a.grids = {"green", "magenta"};
    a.offsets = {"12um,20um,12um", "28um,20um,12um"};
    a.rotations = {"z:0", "z:90"};
    a.output = (dir.path() / "neurons.vdb").string();
    optics::voxelizeFiles(a, database(), nullptr);
    s.scene()["media"]["tissue"]["volume"]["file"] = "neurons.vdb";
    s.write();
    const Loaded l = load(s, {{}, true});
    ASSERT_EQ(l.specimen.neurons.size(), 2u);
    const viewer::NeuronModel& second = l.specimen.neurons[1];
    EXPECT_NEAR(second.pieces.front().aUm.x, 28, 1e-6);  // the soma where it was placed
    EXPECT_NEAR(second.pieces.back().bUm.y, 26, 1e-6);   // the dendrite turned from +x to +y
    EXPECT_EQ(second.channel, 1);
    bool named = false;
    for (const std::string& n : l.specimen.notes) named = named || (n.find("cell.swc (label 2)") != std::string::npos);
    EXPECT_TRUE(named);
}

TEST(ViewerData, SpectralImageLayersAndBands) {
    TempDir dir;
    ExrImage img;
    img.width = 4;
    img.height = 2;
    img.rgb.assign(4 * 2 * 3, 0.5f);
    img.spectral.push_back({"", {650, 450, 550}, std::vector<float>(3 * 8, 1.f)});
    img.spectral.push_back({"fluorescent", {500, 600}, std::vector<float>(2 * 8, 2.f)});
    writeExr((dir.path() / "i.exr").string(), img);
    const viewer::SpectralImage s = viewer::loadSpectralImage(dir.path() / "i.exr");
    ASSERT_EQ(s.layers.size(), 2u);
    EXPECT_EQ(s.layers[0].prefix, "");
    EXPECT_FALSE(s.layers[0].rgb.empty());
    ASSERT_EQ(s.layers[0].bands.size(), 3u);
    EXPECT_EQ(s.layers[0].bands[0].lambdaNm, 450);
    EXPECT_EQ(s.layers[0].bands[2].lambdaNm, 650);
    EXPECT_EQ(s.layers[1].prefix, "fluorescent");
    EXPECT_EQ(s.layers[1].bands.size(), 2u);
    EXPECT_TRUE(s.layers[1].rgb.empty());
    EXPECT_EQ(viewer::spectralChannelWavelength("fluorescent.S0.555,500000nm"), 555.5);
    EXPECT_LT(viewer::spectralChannelWavelength("R"), 0);
}

}  // namespace
}  // namespace fluorosim::testing
