// Scene files with grid media: a "volume" block on a medium and "grid" on its dyes. The grid's own
// units and length unit come from its metadata or from the scene; every bad input names the JSON
// path and the value.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "core/errors.h"
#include "support/fluorescent_scenes.h"
#include "support/temp_dir.h"
#include "scene/scene_loader.h"
#include "volume/density_grid.h"

namespace fluorosim {
namespace {

using json = nlohmann::json;
namespace fs = std::filesystem;

// tissue.vdb in `dir`: "AF488" (2 on a 10^3 block, units uM, length_unit mm), "bare" (no metadata), "mus".
void writeGrids(const fs::path& dir) {
    const auto two = [](int, int, int) { return 2.0; };
    writeVoxelGrids((dir / "tissue.vdb").string(), Affine::scaling(0.01),
                    {{"AF488", {{0, 0, 0}, {9, 9, 9}}, two, {"uM", "mm"}},
                     {"bare", {{0, 0, 0}, {9, 9, 9}}, two, {}},
                     {"mus", {{0, 0, 0}, {9, 9, 9}}, [](int, int, int) { return 0.5; }, {"", "mm"}}});
}

json scene(const json& medium) {
    return json{{"fluorosim_scene", 1},
                {"spectral", {{"range", {"400 nm", "700 nm"}}}},
                {"camera", {{"position", {"0 mm", "0 mm", "-5 mm"}}, {"look_at", {"0 mm", "0 mm", "0 mm"}}, {"fov_y_deg", 30}, {"resolution", {4, 4}}}},
                {"media", {{"tissue", medium}}},
                {"shapes", json::array({json{{"type", "sphere"}, {"center", {"0.05 mm", "0.05 mm", "0.05 mm"}}, {"radius", "0.04 mm"},
                                             {"interior", "tissue"}}})},
                {"lights", json::array({json{{"type", "point"}, {"position", {"0 mm", "0 mm", "-3 mm"}},
                                             {"intensity", {{"lines", json::array({json{{"wavelength", "488 nm"}, {"power", 1}}})}}}}})}};
}

// Each test writes its grids into its own folder: tests run in parallel (ctest -j2).
class SceneVolume : public ::testing::Test {
protected:
    void SetUp() override { writeGrids(dir_.path()); }
    Scene load(const json& j) const;
    std::string error(const json& j) const;
    testing::TempDir dir_;
};

Scene SceneVolume::load(const json& j) const {
    const SpectrumResolver r = [](const std::string& ref, const fs::path& base) { return testing::database().resolve(ref, base); };
    const DyeResolver d = [](const std::string& n, std::optional<double> ec, std::optional<double> qy) { return testing::database().fluorophore(n, ec, qy); };
    return loadSceneFromString(j.dump(), dir_.file("scene.json"), r, d);
}

std::string SceneVolume::error(const json& j) const {
    try {
        (void)load(j);
    } catch (const Error& e) {
        return e.what();
    }
    return "(accepted)";
}

json gridMedium() {
    return json{{"sigma_s", "1 /mm"},
                {"dyes", json::array({json{{"dye", "AF488"}, {"grid", "AF488"}}})},
                {"volume", {{"file", "tissue.vdb"}, {"scattering_grid", "mus"}}}};
}

TEST_F(SceneVolume, GridMediumLoadsWithUnitsFromMetadata) {
    const Scene s = load(scene(gridMedium()));
    const Medium& m = s.media[0];
    ASSERT_FALSE(m.isHomogeneous());
    // Inside the block: 2 uM of AF488 and half the scattering; outside: none.
    ChannelValues ch{};
    m.channelValues(Vec3(0.05, 0.05, 0.05), ch.data());
    EXPECT_NEAR(ch[kFirstDyeChannel], 2e-6, 1e-12);
    EXPECT_NEAR(ch[kScatteringChannel], 0.5, 1e-6);
    EXPECT_DOUBLE_EQ(ch[kSolventChannel], 1.0);
    m.channelValues(Vec3(0.5, 0.5, 0.5), ch.data());
    EXPECT_EQ(ch[kFirstDyeChannel], 0.0);
    EXPECT_NEAR(m.channelMax()[kFirstDyeChannel], 2e-6, 1e-12);
}

TEST_F(SceneVolume, SceneUnitsAndTransformOverrideTheFile) {
    json med = gridMedium();
    med["dyes"][0]["grid"] = "bare";
    med["dyes"][0]["grid_units"] = "nM";
    med["volume"]["length_unit"] = "um";  // voxels of 0.01 um
    med["volume"]["scale"] = 1000;        // back to 0.01 mm
    med["volume"]["translate"] = {"1 mm", "0 mm", "0 mm"};
    med["volume"]["interpolation"] = "nearest";
    const Scene s = load(scene(med));
    ChannelValues ch{};
    s.media[0].channelValues(Vec3(1.05, 0.05, 0.05), ch.data());
    EXPECT_NEAR(ch[kFirstDyeChannel], 2e-9, 1e-15);
    s.media[0].channelValues(Vec3(0.05, 0.05, 0.05), ch.data());
    EXPECT_EQ(ch[kFirstDyeChannel], 0.0);
}

TEST_F(SceneVolume, BadVolumeInputNamesPathAndValue) {
    json med = gridMedium();
    med["dyes"][0]["grid"] = "bare";
    EXPECT_NE(error(scene(med)).find("/media/tissue/dyes/0: grid \"bare\" carries no \"units\" metadata"), std::string::npos) << error(scene(med));
    med["dyes"][0]["grid_units"] = "mm";
    EXPECT_NE(error(scene(med)).find("expected concentration units"), std::string::npos) << error(scene(med));

    med = gridMedium();
    med["dyes"][0]["grid"] = "missing";
    EXPECT_NE(error(scene(med)).find("no grid named \"missing\""), std::string::npos) << error(scene(med));
    EXPECT_NE(error(scene(med)).find("/media/tissue/dyes/0/grid"), std::string::npos) << error(scene(med));

    med = gridMedium();
    med["dyes"][0]["concentration"] = "1 uM";
    EXPECT_NE(error(scene(med)).find("either \"concentration\" or \"grid\""), std::string::npos);

    med = gridMedium();
    med["volume"]["file"] = "nowhere.vdb";
    EXPECT_NE(error(scene(med)).find("nowhere.vdb: no such file"), std::string::npos) << error(scene(med));

    med = gridMedium();
    med["volume"]["interpolation"] = "cubic";
    EXPECT_NE(error(scene(med)).find("/media/tissue/volume/interpolation"), std::string::npos);

    med = gridMedium();
    med.erase("volume");
    EXPECT_NE(error(scene(med)).find("has no \"volume\""), std::string::npos);

    // Only the bare grid: no length unit anywhere.
    med = json{{"sigma_s", "1 /mm"}, {"volume", {{"file", "tissue.vdb"}, {"scattering_grid", "bare"}}}};
    EXPECT_NE(error(scene(med)).find("give \"length_unit\""), std::string::npos) << error(scene(med));
    med["volume"]["length_unit"] = "parsec";
    EXPECT_NE(error(scene(med)).find("/media/tissue/volume/length_unit"), std::string::npos) << error(scene(med));
}

}  // namespace
}  // namespace fluorosim
