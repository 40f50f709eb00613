// Scene loader: a minimal valid scene loads, and every kind of bad input gives a ConfigError/IoError
// whose message names the JSON path and the bad value.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <variant>
#include <vector>

#include "core/errors.h"
#include "database.h"
#include "scene/scene_loader.h"
#include "scene/tissue_presets.h"
#include "support/temp_dir.h"

namespace fluorosim {
namespace {

using json = nlohmann::json;
namespace fs = std::filesystem;

const spectra::Database& db() {
    static const spectra::Database database(fs::path(FLUOROSIM_SOURCE_DIR) / "spectra" / "data");
    return database;
}

const SpectrumResolver& resolver() {
    static const SpectrumResolver r = [](const std::string& ref, const fs::path& base) { return db().resolve(ref, base); };
    return r;
}

const fs::path kSceneFile = fs::temp_directory_path() / "fluorosim_scene_loader_test" / "tiny.json";

// A tiny scene with the structure of samples/cornell/scene.json: one medium with a glass sphere,
// a diffuse floor, a D65 area light and a point light.
json minimalScene() {
    return json::parse(R"({
      "fluorosim_scene": 1,
      "description": "tiny",
      "spectral": {"range": ["400 nm", "700 nm"], "bin_width": "10 nm"},
      "render": {"spp": 4, "seed": 3},
      "camera": {
        "position": ["0 mm", "50 mm", "-200 mm"],
        "look_at": ["0 mm", "50 mm", "0 mm"],
        "up": [0, 1, 0],
        "fov_y_deg": 40,
        "resolution": [8, 8]
      },
      "media": {
        "glass": {"ior": 1.5},
        "water": {"ior": 1.33, "g": 0.7, "sigma_s": "0.5 /mm", "sigma_a": "0.01 /mm"}
      },
      "materials": {
        "white": {"type": "diffuse", "reflectance": 0.7},
        "glass_surface": {"type": "dielectric"}
      },
      "shapes": [
        {"type": "quad", "name": "floor", "origin": ["-100 mm", "0 mm", "-100 mm"], "edge1": ["200 mm", "0 mm", "0 mm"],
         "edge2": ["0 mm", "0 mm", "200 mm"], "material": "white"},
        {"type": "sphere", "name": "ball", "center": ["0 mm", "30 mm", "0 mm"], "radius": "30 mm", "interior": "water",
         "material": "glass_surface"},
        {"type": "quad", "name": "light", "origin": ["-20 mm", "120 mm", "-20 mm"], "edge1": ["40 mm", "0 mm", "0 mm"],
         "edge2": ["0 mm", "0 mm", "40 mm"], "emission": {"radiance": {"reference": "illuminant:D65", "scale": 0.1}}}
      ],
      "lights": [
        {"type": "point", "position": ["0 mm", "100 mm", "-50 mm"], "intensity": 5}
      ]
    })");
}

const DyeResolver& dyeResolver() {
    static const DyeResolver r = [](const std::string& name, std::optional<double> ec, std::optional<double> qy) {
        return db().fluorophore(name, ec, qy);
    };
    return r;
}

Scene load(const json& j) { return loadSceneFromString(j.dump(), kSceneFile, resolver(), dyeResolver()); }

bool contains(const std::string& haystack, const std::string& needle) { return haystack.find(needle) != std::string::npos; }

// Loading must fail with ConfigError (or IoError when allowed) whose message contains every part.
void expectRejectedText(const std::string& text, const std::vector<std::string>& parts, bool ioErrorAllowed = false) {
    try {
        loadSceneFromString(text, kSceneFile, resolver(), dyeResolver());
        ADD_FAILURE() << "the scene was accepted";
    } catch (const ConfigError& e) {
        const std::string msg = e.what();
        EXPECT_TRUE(contains(msg, kSceneFile.string())) << "no file name in: " << msg;
        for (const auto& p : parts) EXPECT_TRUE(contains(msg, p)) << "no " << p << " in: " << msg;
    } catch (const IoError& e) {
        EXPECT_TRUE(ioErrorAllowed) << "IoError: " << e.what();
        for (const auto& p : parts) EXPECT_TRUE(contains(e.what(), p)) << "no " << p << " in: " << e.what();
    } catch (const std::exception& e) {
        ADD_FAILURE() << "wrong exception type: " << e.what();
    }
}

void expectRejected(const json& j, const std::vector<std::string>& parts, bool ioErrorAllowed = false) {
    expectRejectedText(j.dump(), parts, ioErrorAllowed);
}

TEST(SceneLoader, MinimalSceneLoads) {
    const Scene s = load(minimalScene());
    EXPECT_EQ(s.shapes.size(), 3u);
    EXPECT_EQ(s.lights.size(), 2u);
    EXPECT_EQ(s.media.size(), 2u);
    EXPECT_EQ(s.materials.size(), 2u);
    EXPECT_EQ(s.materialNames.size(), s.materials.size());
    int area = 0, point = 0;
    for (const Light& l : s.lights) {
        area += std::holds_alternative<AreaLight>(l);
        point += std::holds_alternative<PointLight>(l);
    }
    EXPECT_EQ(area, 1);
    EXPECT_EQ(point, 1);
    EXPECT_EQ(s.camera.width, 8);
    EXPECT_EQ(s.camera.height, 8);
    EXPECT_DOUBLE_EQ(s.spectral.lambdaMin, 400.0);
    EXPECT_DOUBLE_EQ(s.spectral.lambdaMax, 700.0);
    EXPECT_EQ(s.render.spp, 4);
    EXPECT_EQ(s.render.seed, 3u);
    EXPECT_EQ(s.shapes[0].name, "floor");
    EXPECT_FALSE(s.shapes[0].isInterface);
    EXPECT_TRUE(s.shapes[1].isInterface);
    EXPECT_EQ(s.shapes[1].outsideMedium, kNone);
    EXPECT_NE(s.shapes[1].insideMedium, kNone);
    EXPECT_NE(s.shapes[2].areaLight, kNone);
}

TEST(SceneLoader, CornellSampleLoads) {
    const fs::path file = fs::path(FLUOROSIM_SOURCE_DIR) / "samples" / "cornell" / "scene.json";
    if (!fs::exists(file)) GTEST_SKIP() << file << " not present";
    const Scene s = loadScene(file, resolver());  // a mesh relative to the scene's folder, media, a D65 light
    EXPECT_GE(s.shapes.size(), 1u);
    EXPECT_GE(s.lights.size(), 1u);
}

TEST(SceneLoader, MalformedJson) {
    expectRejectedText("{\n  \"fluorosim_scene\": 1,\n  \"shapes\": [,]\n}\n", {"malformed JSON", "line 3"});
    expectRejectedText("", {"malformed JSON"});
}

TEST(SceneLoader, MissingSceneFileIsIoError) {
    const fs::path f = fs::temp_directory_path() / ("fluorosim_no_such_scene_" + std::to_string(::getpid()) + ".json");
    try {
        loadScene(f, resolver());
        FAIL() << "accepted";
    } catch (const IoError& e) {
        EXPECT_TRUE(contains(e.what(), f.string())) << e.what();
    }
}

TEST(SceneLoader, UnknownTopLevelField) {
    json j = minimalScene();
    j["colour"] = "blue";
    expectRejected(j, {"/colour", "\"blue\"", "unknown field"});
}

TEST(SceneLoader, UnknownNestedField) {
    json j = minimalScene();
    j["media"]["water"]["sigma_t"] = "1 /mm";
    expectRejected(j, {"/media/water/sigma_t", "\"1 /mm\""});
}

TEST(SceneLoader, UnsupportedVersion) {
    json j = minimalScene();
    j["fluorosim_scene"] = 2;
    expectRejected(j, {"/fluorosim_scene", "2"});
}

TEST(SceneLoader, MissingShapes) {
    json j = minimalScene();
    j.erase("shapes");
    expectRejected(j, {"\"shapes\"", "missing"});
}

TEST(SceneLoader, EmptyShapes) {
    json j = minimalScene();
    j["shapes"] = json::array();
    expectRejected(j, {"/shapes", "[]"});
}

TEST(SceneLoader, UnknownMaterialName) {
    json j = minimalScene();
    j["shapes"][0]["material"] = "blak";
    expectRejected(j, {"/shapes/0/material", "\"blak\""});
}

TEST(SceneLoader, UnknownMaterialType) {
    json j = minimalScene();
    j["materials"]["white"]["type"] = "velvet";
    expectRejected(j, {"/materials/white/type", "\"velvet\""});
}

TEST(SceneLoader, UnknownShapeType) {
    json j = minimalScene();
    j["shapes"][0]["type"] = "torus";
    expectRejected(j, {"/shapes/0/type", "\"torus\""});
}

TEST(SceneLoader, UnknownSpectrumReference) {
    json j = minimalScene();
    j["shapes"][2]["emission"]["radiance"]["reference"] = "illuminant:D50";
    expectRejected(j, {"/shapes/2/emission/radiance/reference", "illuminant:D50"});
    json k = minimalScene();
    k["shapes"][2]["emission"]["radiance"] = "illuminant:D50";
    expectRejected(k, {"/shapes/2/emission/radiance", "illuminant:D50"});
    json m = minimalScene();
    m["materials"]["white"]["reflectance"] = "filter:no_such_filter";
    expectRejected(m, {"/materials/white/reflectance", "filter:no_such_filter"});
}

TEST(SceneLoader, NegativeScatteringCoefficient) {
    json j = minimalScene();
    j["media"]["water"]["sigma_s"] = "-1 /mm";
    expectRejected(j, {"/media/water/sigma_s", "\"-1 /mm\""});
}

TEST(SceneLoader, CoefficientWithoutUnit) {
    json j = minimalScene();
    j["media"]["water"]["sigma_a"] = "0.5";
    expectRejected(j, {"/media/water/sigma_a", "\"0.5\""});
    json k = minimalScene();
    k["media"]["water"]["sigma_a"] = 0.5;
    expectRejected(k, {"/media/water/sigma_a", "0.5"});
    json m = minimalScene();
    m["media"]["water"]["sigma_s"] = "0.5 mm";
    expectRejected(m, {"/media/water/sigma_s", "\"0.5 mm\""});
}

TEST(SceneLoader, NanLikeCoefficient) {
    for (const char* bad : {"nan /mm", "NaN /mm", "-nan /mm", "inf /mm", "1e999 /mm"}) {
        SCOPED_TRACE(bad);
        json j = minimalScene();
        j["media"]["water"]["sigma_a"] = bad;
        expectRejected(j, {"/media/water/sigma_a", std::string("\"") + bad + "\""});
    }
}

TEST(SceneLoader, AnisotropyOutOfRange) {
    json j = minimalScene();
    j["media"]["water"]["g"] = 1.0;
    expectRejected(j, {"/media/water/g", "1.0"});
    json k = minimalScene();
    k["media"]["water"]["g"] = -1.5;
    expectRejected(k, {"/media/water/g", "-1.5"});
    json m = minimalScene();
    m["media"]["water"]["g"] = "0.5";
    expectRejected(m, {"/media/water/g", "\"0.5\""});
}

TEST(SceneLoader, ZeroAreaQuad) {
    json j = minimalScene();
    j["shapes"][0]["edge2"] = {"400 mm", "0 mm", "0 mm"};  // parallel to edge1
    expectRejected(j, {"/shapes/0", "zero area", "[\"400 mm\",\"0 mm\",\"0 mm\"]"});
    json k = minimalScene();
    k["shapes"][0]["edge1"] = {"0 mm", "0 mm", "0 mm"};
    expectRejected(k, {"/shapes/0", "zero area", "[\"0 mm\",\"0 mm\",\"0 mm\"]"});
}

TEST(SceneLoader, SphereWithZeroRadius) {
    json j = minimalScene();
    j["shapes"][1]["radius"] = "0 mm";
    expectRejected(j, {"/shapes/1/radius", "\"0 mm\""});
    json k = minimalScene();
    k["shapes"][1]["radius"] = "-3 mm";
    expectRejected(k, {"/shapes/1/radius", "\"-3 mm\""});
}

TEST(SceneLoader, LengthWithWrongUnit) {
    json j = minimalScene();
    j["shapes"][1]["center"] = {"0 mm", "30 /mm", "0 mm"};
    expectRejected(j, {"/shapes/1/center/1", "\"30 /mm\""});
}

TEST(SceneLoader, MissingMeshFile) {
    json j = minimalScene();
    j["shapes"][0] = {{"type", "mesh"}, {"file", "no_such_mesh.obj"}, {"unit", "mm"}, {"material", "white"}};
    expectRejected(j, {"/shapes/0/file", "no_such_mesh.obj"}, /*ioErrorAllowed=*/true);
}

TEST(SceneLoader, WavelengthRangeOutOfBounds) {
    json j = minimalScene();
    j["spectral"]["range"] = {"50 nm", "800 nm"};
    expectRejected(j, {"/spectral/range", "\"50 nm\""});
}

TEST(SceneLoader, WavelengthRangeInverted) {
    json j = minimalScene();
    j["spectral"]["range"] = {"700 nm", "400 nm"};
    expectRejected(j, {"/spectral/range", "\"700 nm\"", "\"400 nm\""});
    json k = minimalScene();
    k["spectral"]["range"] = {"500 nm", "500 nm"};
    expectRejected(k, {"/spectral/range", "\"500 nm\""});
}

TEST(SceneLoader, SpectralLineOutsideRange) {
    json j = minimalScene();
    j["shapes"][2]["emission"]["radiance"] = {{"lines", {{{"wavelength", "900 nm"}, {"power", 1}}}}};
    expectRejected(j, {"/shapes/2/emission/radiance/lines/0/wavelength", "\"900 nm\""});
}

TEST(SceneLoader, SpectralLineInsideRangeLoads) {
    json j = minimalScene();
    j["shapes"][2]["emission"]["radiance"] = {{"lines", {{{"wavelength", "488 nm"}, {"power", 1}}}}};
    EXPECT_NO_THROW(load(j));
}

TEST(SceneLoader, ReflectanceAboveOne) {
    json j = minimalScene();
    j["materials"]["white"]["reflectance"] = 1.5;
    expectRejected(j, {"/materials/white/reflectance", "1.5"});
    json k = minimalScene();
    k["materials"]["white"]["reflectance"] = {{"tabulated", {{"wavelength_nm", {400, 700}}, {"values", {0.5, 1.25}}}}};
    expectRejected(k, {"/materials/white/reflectance", "1.25"});
}

TEST(SceneLoader, NegativeReflectance) {
    json j = minimalScene();
    j["materials"]["white"]["reflectance"] = -0.2;
    expectRejected(j, {"/materials/white/reflectance", "-0.2"});
}

TEST(SceneLoader, SceneWithoutLight) {
    json j = minimalScene();
    j.erase("lights");
    j["shapes"].erase(2);
    expectRejected(j, {"no light"});
}

TEST(SceneLoader, EmissionWithZeroPower) {
    json j = minimalScene();
    j["shapes"][2]["emission"]["radiance"] = 0;
    expectRejected(j, {"/shapes/2/emission/radiance", "0"});
    json k = minimalScene();
    k["shapes"][2]["emission"]["radiance"]["scale"] = 0;
    expectRejected(k, {"/shapes/2/emission/radiance", "\"scale\":0"});
    json m = minimalScene();
    m["lights"][0]["intensity"] = 0;
    expectRejected(m, {"/lights/0/intensity", "0"});
}

TEST(SceneLoader, EmissionOutsideSpectralRange) {
    json j = minimalScene();
    j["shapes"][2]["emission"]["radiance"] = {{"tabulated", {{"wavelength_nm", {750, 800}}, {"values", {1, 1}}}}};
    expectRejected(j, {"/shapes/2/emission/radiance", "750"});
}

TEST(SceneLoader, CameraLookAtEqualsPosition) {
    json j = minimalScene();
    j["camera"]["look_at"] = j["camera"]["position"];
    expectRejected(j, {"/camera/look_at", "[\"0 mm\",\"50 mm\",\"-200 mm\"]"});
}

TEST(SceneLoader, CameraUpParallelToView) {
    json j = minimalScene();
    j["camera"]["up"] = {0, 0, 1};
    expectRejected(j, {"/camera/up", "[0,0,1]"});
}

TEST(SceneLoader, ResolutionOutOfRange) {
    json j = minimalScene();
    j["camera"]["resolution"] = {0, 8};
    expectRejected(j, {"/camera/resolution/0", "0"});
    json k = minimalScene();
    k["camera"]["resolution"] = {8, 100000};
    expectRejected(k, {"/camera/resolution/1", "100000"});
    json m = minimalScene();
    m["camera"]["resolution"] = {8.5, 8};
    expectRejected(m, {"/camera/resolution/0", "8.5"});
}

TEST(SceneLoader, FieldOfViewOutOfRange) {
    json j = minimalScene();
    j["camera"]["fov_y_deg"] = 180;
    expectRejected(j, {"/camera/fov_y_deg", "180"});
}

TEST(SceneLoader, DielectricWithoutMedia) {
    json j = minimalScene();
    j["shapes"][0]["material"] = "glass_surface";
    expectRejected(j, {"/shapes/0/material", "\"glass_surface\""});
}

TEST(SceneLoader, InterfaceWithNonDielectricMaterial) {
    json j = minimalScene();
    j["shapes"][1]["material"] = "white";
    expectRejected(j, {"/shapes/1/material", "\"white\""});
}

TEST(SceneLoader, UnknownInteriorMedium) {
    json j = minimalScene();
    j["shapes"][1]["interior"] = "milk";
    expectRejected(j, {"/shapes/1/interior", "\"milk\""});
    json k = minimalScene();
    k["shapes"][1]["exterior"] = "air";
    expectRejected(k, {"/shapes/1/exterior", "\"air\""});
    json m = minimalScene();
    m["camera"]["medium"] = "milk";
    expectRejected(m, {"/camera/medium", "\"milk\""});
}

TEST(SceneLoader, IorOutOfRange) {
    json j = minimalScene();
    j["media"]["glass"]["ior"] = 0.5;
    expectRejected(j, {"/media/glass/ior", "0.5"});
}

TEST(SceneLoader, BadTabulatedSpectrum) {
    json j = minimalScene();
    j["materials"]["white"]["reflectance"] = {{"tabulated", {{"wavelength_nm", {400, 500, 450}}, {"values", {0.1, 0.2, 0.3}}}}};
    expectRejected(j, {"/materials/white/reflectance/tabulated", "450"});
    json k = minimalScene();
    k["materials"]["white"]["reflectance"] = {{"tabulated", {{"wavelength_nm", {400, 500}}, {"values", {0.1}}}}};
    expectRejected(k, {"/materials/white/reflectance/tabulated"});
}

TEST(SceneLoader, NegativeRenderSpp) {
    json j = minimalScene();
    j["render"]["spp"] = 0;
    expectRejected(j, {"/render/spp", "0"});
}

}  // namespace
}  // namespace fluorosim

namespace fluorosim {
namespace {

TEST(SceneLoaderSemantics, CoefficientReferencesNeedTheirUnit) {
    // A CSV or database spectrum used as a coefficient must state its unit; water absorption is known.
    json j = minimalScene();
    j["media"]["water"]["sigma_a"] = "filter:chroma_ET525-36m";
    expectRejected(j, {"/media/water/sigma_a", "needs its unit"});
    json k = minimalScene();
    k["media"]["water"]["sigma_a"] = "solvent-absorption:water";
    EXPECT_NO_THROW(load(k));
    json m = minimalScene();
    m["media"]["water"]["sigma_a"] = {{"reference", "solvent-absorption:water"}, {"unit", "/m"}};
    expectRejected(m, {"/media/water/sigma_a/unit", "1/mm"});
    json q = minimalScene();
    q["materials"]["white"]["reflectance"] = "0.5";
    expectRejected(q, {"/materials/white/reflectance", "JSON number"});
}

TEST(SceneLoaderSemantics, DielectricBetweenEqualIndicesIsANullInterface) {
    json j = minimalScene();
    j["media"]["water"]["ior"] = 1.0;  // the ball's exterior is vacuum (n = 1)
    const Scene scene = load(j);
    EXPECT_EQ(scene.shapes[1].material, kNone);
    EXPECT_TRUE(scene.shapes[1].isInterface);
    const Scene glass = load(minimalScene());
    EXPECT_NE(glass.shapes[1].material, kNone);
}

TEST(SceneLoaderSemantics, MissingMeshIsAnIoErrorNamingTheField) {
    json j = minimalScene();
    j["shapes"][0] = {{"type", "mesh"}, {"file", "no_such_mesh.obj"}, {"unit", "mm"}, {"material", "white"}};
    try {
        load(j);
        FAIL() << "expected IoError";
    } catch (const IoError& e) {
        EXPECT_TRUE(contains(e.what(), "/shapes/0/file")) << e.what();
        EXPECT_TRUE(contains(e.what(), "no_such_mesh.obj")) << e.what();
    }
}

}  // namespace
}  // namespace fluorosim

namespace fluorosim {
namespace {

TEST(SceneLoaderDyes, MolarAndMassConcentrations) {
    json j = minimalScene();
    j["media"]["water"]["dyes"] = json::array({{{"dye", "AF488"}, {"concentration", "10 uM"}},
                                               {{"dye", "Alexa Fluor 568"}, {"concentration", "0.5 g/L"}, {"molar_mass", "791.8 g/mol"}}});
    const Scene scene = load(j);
    const auto& dyes = scene.media[1].dyes();
    ASSERT_EQ(dyes.size(), 2u);
    EXPECT_EQ(dyes[0].dye.id(), "alexa_fluor_488");
    EXPECT_DOUBLE_EQ(dyes[0].molar, 1e-5);
    EXPECT_DOUBLE_EQ(dyes[1].molar, 0.5 / 791.8);
    EXPECT_TRUE(scene.warnings.empty());
    EXPECT_EQ(scene.render.fluorescence, FluorescenceModel::Full);
}

// A line outside a medium's coefficient table would meet a 0 made up by extrapolation.
TEST(SceneLoaderDyes, LightLineOutsideACoefficientTableIsAnError) {
    json j = minimalScene();
    j["media"]["water"]["sigma_a"] = {{"unit", "/mm"}, {"tabulated", {{"wavelength_nm", {500, 600}}, {"values", {0.1, 0.2}}}}};
    j["lights"][0]["intensity"] = {{"lines", {{{"wavelength", "488 nm"}, {"power", 1}}}}};
    expectRejected(j, {"/media/water/sigma_a", "500 to 600 nm", "488 nm"});
    j["lights"][0]["intensity"] = {{"lines", {{{"wavelength", "532 nm"}, {"power", 1}}}}};
    EXPECT_NO_THROW(load(j));
}

TEST(SceneLoaderDyes, FluorescenceModelIsSelectable) {
    json j = minimalScene();
    j["render"]["fluorescence"] = "paper";
    EXPECT_EQ(load(j).render.fluorescence, FluorescenceModel::Paper);
    j["render"]["fluorescence"] = "none";
    EXPECT_EQ(load(j).render.fluorescence, FluorescenceModel::None);
    j["render"]["fluorescence"] = "unbiased";
    expectRejected(j, {"/render/fluorescence", "\"full\", \"paper\" or \"none\"", "\"unbiased\""});
}

TEST(SceneLoaderDyes, BadDyeInput) {
    auto withDye = [](json dye) {
        json j = minimalScene();
        j["media"]["water"]["dyes"] = json::array({dye});
        return j;
    };
    expectRejected(withDye({{"dye", "AF489"}, {"concentration", "1 uM"}}), {"/media/water/dyes/0/dye", "alexa_fluor_488"});
    expectRejected(withDye({{"dye", "AF488"}, {"concentration", "-1 uM"}}), {"/media/water/dyes/0/concentration", "non-negative"});
    expectRejected(withDye({{"dye", "AF488"}, {"concentration", "0.1 g/L"}}), {"/media/water/dyes/0/concentration", "molar_mass"});
    expectRejected(withDye({{"dye", "AF488"}, {"concentration", "10 mm"}}), {"/media/water/dyes/0/concentration", "10 mm"});
    expectRejected(withDye({{"dye", "AF488"}, {"concentration", "1 uM"}, {"quantum_yield", 1.2}}), {"/media/water/dyes/0/quantum_yield"});
    expectRejected(withDye({{"dye", "alexa_fluor_350"}, {"concentration", "1 uM"}}), {"/media/water/dyes/0/dye", "extinction"});
    EXPECT_NO_THROW(load(withDye({{"dye", "alexa_fluor_350"}, {"concentration", "1 uM"}, {"extinction_peak_M-1cm-1", 19000}, {"quantum_yield", 0.5}})));
    // Zero concentration is legal.
    EXPECT_NO_THROW(load(withDye({{"dye", "AF488"}, {"concentration", "0 M"}})));
}

}  // namespace
}  // namespace fluorosim

namespace fluorosim {
namespace {

TEST(SceneLoaderCoverage, ConductorIndexMustCoverTheRange) {
    json j = minimalScene();
    j["materials"]["metal"] = {{"type", "conductor"},
                               {"eta", {{"tabulated", {{"wavelength_nm", {450, 650}}, {"values", {1.2, 1.1}}}}}},
                               {"k", 3.0}};
    expectRejected(j, {"/materials/metal/eta", "must cover the whole range"});
}

TEST(SceneLoaderCoverage, PartialTablesWarn) {
    json j = minimalScene();
    j["materials"]["white"]["reflectance"] = {{"tabulated", {{"wavelength_nm", {450, 650}}, {"values", {0.5, 0.5}}}}};
    const Scene scene = load(j);
    ASSERT_FALSE(scene.warnings.empty());
    EXPECT_TRUE(contains(scene.warnings[0], "/materials/white/reflectance")) << scene.warnings[0];
    EXPECT_TRUE(contains(scene.warnings[0], "0 outside its table")) << scene.warnings[0];
}

// ---- JSON structure: duplicates, nesting, numbers beyond range ----

TEST(SceneLoader, DuplicateKeysAreRefusedNamingKeyAndPath) {
    const std::string text = minimalScene().dump();
    expectRejectedText(text.substr(0, text.size() - 1) + ",\"camera\":{}}", {"/camera", "duplicate key \"camera\""});
    json j = minimalScene();
    std::string t = j.dump();
    t.insert(t.find("\"radius\""), "\"radius\":\"1 mm\",");
    expectRejectedText(t, {"/shapes/1/radius", "duplicate key \"radius\""});
}

TEST(SceneLoader, DeepNestingIsRefusedWhileParsing) {
    // 100 000 levels used to overflow the stack in the recursive dump() of the error message.
    const std::string text = minimalScene().dump();
    const std::string deep = std::string(100000, '[') + std::string(100000, ']');
    expectRejectedText(text.substr(0, text.size() - 1) + ",\"notes\":" + deep + "}", {"/notes/0/0", "nested deeper than 64"});
    std::string objects;
    for (int i = 0; i < 100000; ++i) objects += "{\"a\":";
    objects += "1" + std::string(100000, '}');
    expectRejectedText(text.substr(0, text.size() - 1) + ",\"microscope\":" + objects + "}", {"/microscope/a/a", "nested deeper"});
    // Up to the limit is fine for the parser (the loader then refuses the unknown field).
    expectRejectedText(text.substr(0, text.size() - 1) + ",\"zzz\":" + std::string(60, '[') + std::string(60, ']') + "}",
                       {"/zzz", "unknown field"});
}

TEST(SceneLoader, NumberBeyondDoubleNamesTheField) {
    std::string text = minimalScene().dump();
    text.insert(text.find("\"fov_y_deg\":") + 12, "1e999,\"x\":");
    expectRejectedText(text, {"/camera/fov_y_deg", "1e999"});
}

TEST(SceneLoader, UnsignedIntegersDoNotWrapIntoRange) {
    // 2^64 - 1 read as int64_t is -1, which is in range for majorant_cell_voxels; 2^63 is -2^63.
    std::string text = minimalScene().dump();
    const auto p = text.find("\"seed\":3");
    expectRejectedText(std::string(text).replace(p, 8, "\"seed\":18446744073709551615"), {"/render/seed", "18446744073709551615"});
    expectRejectedText(std::string(text).replace(p, 8, "\"seed\":9223372036854775808"), {"/render/seed", "9223372036854775808"});
}

TEST(SceneLoader, EmissionThatWouldOverflowIsRefused) {
    json j = minimalScene();
    j["lights"][0]["intensity"] = 1e308;
    expectRejected(j, {"/lights/0/intensity", "1e+308", "1e30"});
}

TEST(SceneLoader, EchoedValuesAreExcerpts) {
    json j = minimalScene();
    j["shapes"][1]["radius"] = "1 " + std::string(1 << 20, 'x');
    try {
        load(j);
        ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
        EXPECT_LT(std::string(e.what()).size(), 600u);
        EXPECT_TRUE(contains(e.what(), "(1048578 characters)")) << e.what();
    }
}

TEST(SceneLoader, FoldersAreNotSceneFiles) {
    const testing::TempDir dir;
    try {
        loadScene(dir.path(), resolver());
        FAIL() << "accepted";
    } catch (const IoError& e) {
        EXPECT_TRUE(contains(e.what(), "is a folder")) << e.what();
    }
    fs::create_directory(dir.file("block.obj"));
    json j = minimalScene();
    j["shapes"].push_back({{"type", "mesh"}, {"file", (dir.path() / "block.obj").string()}, {"unit", "mm"}, {"material", "white"}});
    expectRejected(j, {"/shapes/3/file", "is a folder"}, true);
}

TEST(SceneLoaderSemantics, TissuePresetsGiveDefaultsThatFieldsOverride) {
    json j = minimalScene();
    j["media"]["water"] = {{"tissue", "grey_matter"}};
    Scene scene = load(j);
    const Medium* grey = nullptr;
    for (const Medium& m : scene.media)
        if (m.name() == "water") grey = &m;
    ASSERT_NE(grey, nullptr);
    // Jacques 2013: mu_s' = 2.42 /mm (lambda / 500 nm)^-1.611; with g 0.88, mu_s = mu_s' / 0.12 (18-25 /mm at 488 nm).
    for (double lambda : {488.0, 561.0, 640.0})
        EXPECT_NEAR(grey->scattering()(lambda), 2.42 * std::pow(lambda / 500, -1.611) / 0.12, 1e-5 * grey->scattering()(lambda)) << lambda;
    EXPECT_NEAR(grey->scattering()(488), 20.97, 0.01);
    EXPECT_DOUBLE_EQ(grey->ior(), 1.365);
    EXPECT_DOUBLE_EQ(grey->solventAbsorption()(561), 0.02);
    // Fields override the preset.
    j["media"]["water"] = {{"tissue", "cleared_idisco"}, {"sigma_s", "2 /mm"}};
    scene = load(j);
    for (const Medium& m : scene.media)
        if (m.name() == "water") {
            EXPECT_DOUBLE_EQ(m.scattering()(500), 2.0);
            EXPECT_DOUBLE_EQ(m.ior(), 1.56);
            EXPECT_DOUBLE_EQ(m.phase().g(), 0.9);
        }
    for (const TissuePreset& p : tissuePresets()) {
        EXPECT_FALSE(p.source.empty()) << p.name;
        EXPECT_GT(p.ior, 1.3) << p.name;
        EXPECT_LT(p.g, 1.0) << p.name;
    }
    j["media"]["water"] = {{"tissue", "gray_matter"}};
    expectRejected(j, {"/media/water/tissue", "unknown tissue preset \"gray_matter\"", "grey_matter, white_matter"});
}

}  // namespace
}  // namespace fluorosim
