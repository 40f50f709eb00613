// The bad-input matrix (docs/reliability.md): malformed scene JSON, meshes, VDB files, SWC files,
// spectrum CSV files and command-line values, each run through the built CLI. Every case must end
// with a one-line error that names the file or option, the field and the value, exit code 2 (invalid
// input) or 3 (I/O), within the runner's timeout (a hang fails the case), and without memory beyond
// the cap: the cases run with FLUOROSIM_MEMORY_CAP=512MiB and their peak memory is checked.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "support/cli_runner.h"
#include "volume/density_grid.h"

namespace fluorosim {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using testing::TempDir;

#if defined(__SANITIZE_ADDRESS__)
// ASan's shadow memory and quarantine inflate the resident size; the check runs in normal builds.
constexpr bool kMeasureMemory = false;
#else
constexpr bool kMeasureMemory = true;
#endif
constexpr const char* kCap = "512MiB";
constexpr long kCapKb = 512 * 1024;
// What the process holds besides what the cap governs: code, libraries, the spectral database.
constexpr long kBaselineKb = 256 * 1024;

const fs::path kSource = FLUOROSIM_SOURCE_DIR;

// A small valid scene: 4x4 pixels at 1 spp render in milliseconds, so a case that is wrongly
// accepted still ends quickly (and fails on its exit code).
json baseScene() {
    return json::parse(R"({
      "fluorosim_scene": 1,
      "spectral": {"range": ["400 nm", "700 nm"], "bin_width": "50 nm"},
      "render": {"spp": 1, "seed": 1},
      "camera": {"position": ["0 mm", "50 mm", "-200 mm"], "look_at": ["0 mm", "50 mm", "0 mm"], "fov_y_deg": 40, "resolution": [4, 4]},
      "materials": {"white": {"type": "diffuse", "reflectance": 0.7}},
      "shapes": [
        {"type": "sphere", "name": "ball", "center": ["0 mm", "30 mm", "0 mm"], "radius": "30 mm", "material": "white"}
      ],
      "lights": [{"type": "point", "position": ["0 mm", "200 mm", "0 mm"], "intensity": 1000}]
    })");
}

std::string nested(size_t depth, const std::string& inner = "1") { return std::string(depth, '[') + inner + std::string(depth, ']'); }

// A scene with a mesh shape reading `file`.
json meshScene(const std::string& file) {
    json j = baseScene();
    j["shapes"].push_back({{"type", "mesh"}, {"file", file}, {"unit", "mm"}, {"material", "white"}});
    return j;
}

// A scene whose sphere's reflectance comes from the CSV file `file`.
json csvScene(const std::string& file) {
    json j = baseScene();
    j["materials"]["white"]["reflectance"] = file;
    return j;
}

// A scene with a grid medium reading grid `grid` from the VDB file `file`.
json vdbScene(const std::string& file, const std::string& grid = "density") {
    json j = baseScene();
    j["media"] = {{"tissue", {{"sigma_s", "1 /mm"}, {"volume", {{"file", file}, {"scattering_grid", grid}, {"length_unit", "mm"}}}}}};
    j["shapes"][0].erase("material");
    j["shapes"][0]["interior"] = "tissue";
    return j;
}

fs::path writeVdb(const TempDir& dir, const std::string& name, double value = 1.0) {
    const fs::path p = dir.file(name);
    writeVoxelGrids(p.string(), Affine::scaling(1.0), {{"density", {{0, 0, 0}, {7, 7, 7}}, [value](int, int, int) { return value; }, {}}});
    return p;
}

std::string readBytes(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::string swcLine(int id, int type, double x, double y, double z, double r, int parent) {
    std::ostringstream os;
    os << id << " " << type << " " << x << " " << y << " " << z << " " << r << " " << parent << "\n";
    return os.str();
}

struct Case {
    std::string name;
    std::string input;  // category, for the table in docs/reliability.md
    // Writes what the case needs into `dir` and returns the command's arguments.
    std::function<std::vector<std::string>(const TempDir& dir)> args;
    int exitCode;
    // Fragments the message must hold (file, field, value); "{dir}" stands for the case's folder.
    std::vector<std::string> mentions;
};

std::vector<std::string> render(const fs::path& scene, const TempDir& dir, std::vector<std::string> extra = {}) {
    std::vector<std::string> a{"render", scene.string(), "-o", dir.file("out.exr").string(), "--threads", "1"};
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
}

// A render of the base scene with `edit` applied.
std::function<std::vector<std::string>(const TempDir&)> scene(std::function<void(json&)> edit) {
    return [edit](const TempDir& dir) {
        json j = baseScene();
        edit(j);
        return render(dir.write("scene.json", j.dump()), dir);
    };
}

// A render of the scene text `text`, as written.
std::function<std::vector<std::string>(const TempDir&)> sceneText(std::function<std::string()> text) {
    return [text](const TempDir& dir) { return render(dir.write("scene.json", text()), dir); };
}

std::function<std::vector<std::string>(const TempDir&)> cli(std::vector<std::string> args) {
    return [args](const TempDir& dir) {
        std::vector<std::string> a;
        for (std::string s : args) {
            for (size_t p; (p = s.find("{dir}")) != std::string::npos;) s.replace(p, 5, dir.path().string());
            for (size_t p; (p = s.find("{scene}")) != std::string::npos;) s.replace(p, 7, dir.write("scene.json", baseScene().dump()).string());
            a.push_back(s);
        }
        return a;
    };
}

// voxelize with an SWC file holding `text`.
std::function<std::vector<std::string>(const TempDir&)> swcText(std::function<std::string()> text,
                                                                 std::vector<std::string> extra = {"--voxel", "1um"}) {
    return [text, extra](const TempDir& dir) {
        std::vector<std::string> a{"voxelize", dir.write("cell.swc", text()).string(), "--dye", "AF488", "--concentration", "10uM",
                                   "-o", dir.file("out.vdb").string(), "--threads", "1"};
        a.insert(a.end(), extra.begin(), extra.end());
        return a;
    };
}

std::function<std::vector<std::string>(const TempDir&)> swc(std::string text) {
    return swcText([text] { return text; });
}

std::function<std::vector<std::string>(const TempDir&)> voxelizeSample(std::vector<std::string> extra) {
    return [extra](const TempDir& dir) {
        std::vector<std::string> a{"voxelize", (kSource / "samples/neurons/C231296A-P3.CNG.swc").string(), "--dye", "AF488",
                                   "--concentration", "10uM", "-o", dir.file("out.vdb").string()};
        a.insert(a.end(), extra.begin(), extra.end());
        return a;
    };
}

// A render whose sphere reflectance is read from a CSV file holding `text`.
std::function<std::vector<std::string>(const TempDir&)> csvText(std::function<std::string()> text) {
    return [text](const TempDir& dir) {
        dir.write("refl.csv", text());
        return render(dir.write("scene.json", csvScene("refl.csv").dump()), dir);
    };
}

std::function<std::vector<std::string>(const TempDir&)> csv(std::string text) {
    return csvText([text] { return text; });
}

// A render with a mesh file holding `text` (binary as given).
std::function<std::vector<std::string>(const TempDir&)> mesh(std::string name, std::string text) {
    return [name, text](const TempDir& dir) {
        dir.write(name, text);
        return render(dir.write("scene.json", meshScene(name).dump()), dir);
    };
}

// A render with a VDB file made by `make` from a valid one.
std::function<std::vector<std::string>(const TempDir&)> vdb(std::function<void(const fs::path&)> make, std::string grid = "density") {
    return [make, grid](const TempDir& dir) {
        const fs::path f = writeVdb(dir, "grid.vdb");
        make(f);
        return render(dir.write("scene.json", vdbScene("grid.vdb", grid).dump()), dir);
    };
}

void corrupt(const fs::path& f, const std::function<void(std::string&)>& edit) {
    std::string b = readBytes(f);
    edit(b);
    std::ofstream(f, std::ios::binary | std::ios::trunc) << b;
}

const std::string kPlyHeader = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                               "element face 1\nproperty list uchar int vertex_indices\nend_header\n";

// Large inputs are built when a case runs, not when the cases are registered (every test process
// registers all of them).
std::string huge() { return std::string(50 << 20, 'x'); }  // 50 MB

std::vector<Case> cases() {
    std::vector<Case> c;
    // ---- scene JSON ----
    c.push_back({"TrailingComma", "scene JSON", sceneText([] { return std::string("{\"fluorosim_scene\": 1, \"shapes\": [,]}"); }), 2,
                 {"scene.json", "/shapes", "malformed JSON", "line 1"}});
    c.push_back({"TruncatedScene", "scene JSON", sceneText([] { const std::string t = baseScene().dump(); return t.substr(0, t.size() / 2); }), 2,
                 {"scene.json", "malformed JSON"}});
    c.push_back({"EmptySceneFile", "scene JSON", sceneText([] { return std::string(); }), 2, {"scene.json", "malformed JSON"}});
    c.push_back({"DeepNestingInDescription", "scene JSON", sceneText([] {
                     std::string t = baseScene().dump();
                     return t.substr(0, t.size() - 1) + ", \"description\": " + nested(100000) + "}";
                 }), 2, {"scene.json", "/description/0/0", "nested deeper than 64"}});
    c.push_back({"DeepNestingInUnknownField", "scene JSON", sceneText([] {
                     std::string t = baseScene().dump();
                     return t.substr(0, t.size() - 1) + ", \"zzz\": " + nested(100000, "{}") + "}";
                 }), 2, {"scene.json", "/zzz/0", "nested deeper"}});
    c.push_back({"DeepNestedObjectsInMicroscope", "scene JSON", sceneText([] {
                     std::string deep;
                     for (int i = 0; i < 100000; ++i) deep += "{\"a\":";
                     deep += "1" + std::string(100000, '}');
                     std::string t = baseScene().dump();
                     return t.substr(0, t.size() - 1) + ", \"microscope\": " + deep + "}";
                 }), 2, {"scene.json", "/microscope/a/a", "nested deeper"}});
    c.push_back({"DuplicateTopLevelKey", "scene JSON", sceneText([] {
                     std::string t = baseScene().dump();
                     return t.substr(0, t.size() - 1) + ", \"render\": {\"spp\": 2}}";
                 }), 2, {"scene.json", "duplicate key \"render\""}});
    c.push_back({"DuplicateNestedKey", "scene JSON", sceneText([] {
                     std::string t = baseScene().dump();
                     const auto p = t.find("\"radius\"");
                     return t.insert(p, "\"radius\": \"1 mm\", ");
                 }), 2, {"scene.json", "/shapes/0", "duplicate key \"radius\""}});
    c.push_back({"NumberBeyondDouble", "scene JSON", sceneText([] {
                     std::string t = baseScene().dump();
                     const auto p = t.find("40");  // fov_y_deg
                     return t.replace(p, 2, "1e999");
                 }), 2, {"scene.json", "/camera/fov_y_deg", "1e999"}});
    c.push_back({"FovOutOfRange", "scene JSON", scene([](json& j) { j["camera"]["fov_y_deg"] = 180; }), 2,
                 {"/camera/fov_y_deg", "180"}});
    c.push_back({"LengthOverflowsInMillimetres", "scene JSON", scene([](json& j) { j["camera"]["position"][0] = "1e308 m"; }), 2,
                 {"/camera/position/0", "1e308 m", "not finite"}});
    c.push_back({"RadiusNaN", "scene JSON", scene([](json& j) { j["shapes"][0]["radius"] = "nan mm"; }), 2,
                 {"/shapes/0/radius", "nan mm"}});
    c.push_back({"RadiusInfinite", "scene JSON", scene([](json& j) { j["shapes"][0]["radius"] = "inf mm"; }), 2,
                 {"/shapes/0/radius", "inf mm"}});
    c.push_back({"RadiusNegative", "scene JSON", scene([](json& j) { j["shapes"][0]["radius"] = "-1 mm"; }), 2,
                 {"/shapes/0/radius", "-1 mm"}});
    c.push_back({"UnknownUnit", "scene JSON", scene([](json& j) { j["shapes"][0]["radius"] = "5 parsec"; }), 2,
                 {"/shapes/0/radius", "5 parsec", "unknown or mismatched unit"}});
    c.push_back({"HugeUnitString", "scene JSON", scene([](json& j) { j["shapes"][0]["radius"] = "1 " + huge(); }), 2,
                 {"/shapes/0/radius", "xxxx...", "52428802 characters"}});
    c.push_back({"HugeUnknownKey", "scene JSON", scene([](json& j) { j[huge().substr(0, 1 << 20)] = 1; }), 2,
                 {"scene.json", "unknown field", "1048576 characters"}});
    c.push_back({"ZeroResolution", "scene JSON", scene([](json& j) { j["camera"]["resolution"] = {0, 10}; }), 2,
                 {"/camera/resolution/0", "0"}});
    c.push_back({"ResolutionOneBillion", "scene JSON", scene([](json& j) { j["camera"]["resolution"] = {1000000000, 1}; }), 2,
                 {"/camera/resolution/0", "1000000000"}});
    c.push_back({"ResolutionAsFloat1e9", "scene JSON", scene([](json& j) { j["camera"]["resolution"] = {1e9, 1e9}; }), 2,
                 {"/camera/resolution/0", "expected an integer"}});
    c.push_back({"Resolution8192With4000Bins", "scene JSON", scene([](json& j) {
                     j["camera"]["resolution"] = {8192, 8192};
                     j["spectral"] = {{"range", {"400 nm", "800 nm"}}, {"bin_width", "0.1 nm"}};
                 }), 2, {"/camera/resolution", "8192x8192", "4000 spectral bins", "memory cap of 512 MiB"}});
    c.push_back({"SppTwoToThe63InScene", "scene JSON", sceneText([] {
                     std::string t = baseScene().dump();
                     const auto p = t.find("\"spp\":1");
                     return t.replace(p, 7, "\"spp\":9223372036854775808");
                 }), 2, {"/render/spp", "9223372036854775808"}});
    c.push_back({"MaxDepthZero", "scene JSON", scene([](json& j) { j["render"]["max_depth"] = 0; }), 2, {"/render/max_depth", "0"}});
    c.push_back({"SeedNegativeInScene", "scene JSON", scene([](json& j) { j["render"]["seed"] = -1; }), 2, {"/render/seed", "-1"}});
    c.push_back({"MajorantCellsTwoToThe64", "scene JSON", sceneText([] {
                     json j = vdbScene("grid.vdb");
                     j["media"]["tissue"]["volume"]["majorant_cell_voxels"] = 1;
                     std::string t = j.dump();
                     const auto p = t.find("\"majorant_cell_voxels\":1");
                     return t.replace(p, 24, "\"majorant_cell_voxels\":18446744073709551615");
                 }), 2, {"/media/tissue/volume/majorant_cell_voxels", "18446744073709551615"}});
    c.push_back({"BinWidthZero", "scene JSON", scene([](json& j) { j["spectral"]["bin_width"] = "0 nm"; }), 2,
                 {"/spectral/bin_width", "0 nm"}});
    c.push_back({"RangeReversed", "scene JSON", scene([](json& j) { j["spectral"]["range"] = {"700 nm", "400 nm"}; }), 2,
                 {"/spectral/range", "700 nm"}});
    c.push_back({"Intensity1e308", "scene JSON", scene([](json& j) { j["lights"][0]["intensity"] = 1e308; }), 2,
                 {"/lights/0/intensity", "1e+308", "overflow"}});
    c.push_back({"LinePower1e308", "scene JSON", scene([](json& j) {
                     j["lights"][0]["intensity"] = {{"lines", {{{"wavelength", "500 nm"}, {"power", 1e308}}}}};
                 }), 2, {"/lights/0/intensity/lines/0/power", "1e+308"}});
    c.push_back({"CoefficientBeyondDouble", "scene JSON", scene([](json& j) { j["media"] = {{"m", {{"sigma_a", "1e400 /mm"}}}}; }), 2,
                 {"/media/m/sigma_a", "1e400 /mm"}});
    c.push_back({"StringWhereNumber", "scene JSON", scene([](json& j) { j["camera"]["fov_y_deg"] = "wide"; }), 2,
                 {"/camera/fov_y_deg", "wide", "expected a number"}});
    c.push_back({"SceneIsDirectory", "scene JSON", cli({"render", "{dir}", "-o", "{dir}/out.exr"}), 3, {"{dir}", "is a folder"}});
    c.push_back({"SceneIsDevNull", "scene JSON", cli({"render", "/dev/null", "-o", "{dir}/out.exr"}), 2, {"/dev/null", "malformed JSON"}});
    c.push_back({"SceneIsDevZero", "scene JSON", cli({"render", "/dev/zero", "-o", "{dir}/out.exr"}), 2, {"/dev/zero", "64 MiB"}});
    c.push_back({"SceneMissing", "scene JSON", cli({"render", "{dir}/nothing.json", "-o", "{dir}/out.exr"}), 3,
                 {"{dir}/nothing.json", "cannot open"}});
    // ---- meshes ----
    c.push_back({"MeshIsDirectory", "mesh", [](const TempDir& dir) {
                     fs::create_directory(dir.file("block.obj"));
                     return render(dir.write("scene.json", meshScene("block.obj").dump()), dir);
                 }, 3, {"/shapes/1/file", "block.obj", "is a folder"}});
    c.push_back({"MeshMissing", "mesh", [](const TempDir& dir) { return render(dir.write("scene.json", meshScene("none.obj").dump()), dir); }, 3,
                 {"/shapes/1/file", "none.obj", "not found"}});
    c.push_back({"MeshGarbageObj", "mesh", mesh("bad.obj", "v 1 2\nf 1 2 3 4 5 6 7\nthis is not OBJ\n\x01\x02"), 3,
                 {"/shapes/1/file", "bad.obj"}});
    c.push_back({"MeshTruncatedPly", "mesh", mesh("cut.ply", kPlyHeader + "0 0 0\n1 0 0\n"), 2, {"/shapes/1/file", "cut.ply", "no triangles"}});
    c.push_back({"MeshPlyClaimsBillionVertices", "mesh", mesh("big.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\n"
                                                                         "property float x\nproperty float y\nproperty float z\n"
                                                                         "end_header\n" + std::string(64, '\0')), 3,
                 {"/shapes/1/file", "big.ply"}});
    c.push_back({"MeshWithoutTriangles", "mesh", mesh("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"), 3,
                 {"/shapes/1/file", "points.obj", "cannot read mesh"}});
    c.push_back({"MeshEmptyFile", "mesh", mesh("empty.ply", ""), 3, {"/shapes/1/file", "empty.ply"}});
    c.push_back({"MeshUnknownUnit", "mesh", [](const TempDir& dir) {
                     dir.write("t.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
                     json j = meshScene("t.obj");
                     j["shapes"][1]["unit"] = "furlong";
                     return render(dir.write("scene.json", j.dump()), dir);
                 }, 2, {"/shapes/1/unit", "furlong"}});
    // ---- spectrum CSV ----
    c.push_back({"CsvIsDirectory", "spectrum CSV", [](const TempDir& dir) {
                     fs::create_directory(dir.file("refl.csv"));
                     return render(dir.write("scene.json", csvScene("refl.csv").dump()), dir);
                 }, 3, {"/materials/white/reflectance", "refl.csv", "is a folder"}});
    c.push_back({"CsvIsDevZero", "spectrum CSV", [](const TempDir& dir) {
                     return render(dir.write("scene.json", csvScene("/dev/zero").dump()), dir);
                 }, 3, {"/materials/white/reflectance", "/dev/zero", "not a regular file"}});
    c.push_back({"CsvMissing", "spectrum CSV", [](const TempDir& dir) { return render(dir.write("scene.json", csvScene("none.csv").dump()), dir); },
                 3, {"/materials/white/reflectance", "none.csv"}});
    c.push_back({"CsvEmpty", "spectrum CSV", csv(""), 2, {"/materials/white/reflectance", "refl.csv", "header"}});
    c.push_back({"CsvBadHeader", "spectrum CSV", csv("lambda,value\n400,0.5\n"), 2, {"refl.csv", "lambda,value"}});
    c.push_back({"CsvNotANumber", "spectrum CSV", csv("wavelength_nm,r\n400,0.5\n500,half\n"), 2, {"refl.csv:3", "\"r\"", "half"}});
    c.push_back({"CsvDecreasingWavelengths", "spectrum CSV", csv("wavelength_nm,r\n500,0.5\n400,0.5\n"), 2, {"refl.csv:3", "400", "500"}});
    c.push_back({"CsvNegativeValue", "spectrum CSV", csv("wavelength_nm,r\n400,0.5\n500,-0.5\n"), 2, {"refl.csv:3", "-0.5"}});
    c.push_back({"CsvNaNValue", "spectrum CSV", csv("wavelength_nm,r\n400,nan\n500,0.5\n"), 2, {"refl.csv:2", "nan"}});
    c.push_back({"CsvInfWavelength", "spectrum CSV", csv("wavelength_nm,r\n400,0.5\ninf,0.5\n"), 2, {"refl.csv:3", "inf"}});
    c.push_back({"CsvHugeCell", "spectrum CSV", csvText([] { return "wavelength_nm,r\n400,0.5\n500," + std::string(10 << 20, '7') + "x\n"; }), 2,
                 {"refl.csv:3", "77777", "characters"}});
    c.push_back({"CsvMissingColumn", "spectrum CSV", csv("wavelength_nm,r\n400,0.5\n500\n"), 2, {"refl.csv:3", "missing value"}});
    // ---- VDB files ----
    c.push_back({"VdbGridTypeLengthCorrupt", "VDB", vdb([](const fs::path& f) {
                     corrupt(f, [](std::string& b) {
                         const auto p = b.find("Tree_float_5_4_3");
                         b.replace(p - 4, 4, std::string("\xff\xff\xff\x7f", 4));
                     });
                 }), 3, {"/media/tissue/volume/file", "grid.vdb", "corrupt OpenVDB file"}});
    c.push_back({"VdbGridCountCorrupt", "VDB", vdb([](const fs::path& f) {
                     corrupt(f, [](std::string& b) {
                         const auto p = b.find("density");  // the first descriptor follows the grid count
                         b.replace(p - 8, 4, std::string("\xff\xff\xff\x0f", 4));
                     });
                 }), 3, {"grid.vdb", "corrupt OpenVDB file"}});
    c.push_back({"VdbTruncated", "VDB", vdb([](const fs::path& f) {
                     corrupt(f, [](std::string& b) { b.resize(b.size() / 2); });
                 }), 3, {"/media/tissue/volume/file", "grid.vdb"}});
    c.push_back({"VdbIsText", "VDB", vdb([](const fs::path& f) { std::ofstream(f, std::ios::trunc) << "not a volume\n"; }), 3,
                 {"/media/tissue/volume/file", "grid.vdb", "cannot read as an OpenVDB file"}});
    c.push_back({"VdbEmptyFile", "VDB", vdb([](const fs::path& f) { std::ofstream(f, std::ios::trunc).close(); }), 3,
                 {"/media/tissue/volume/file", "grid.vdb"}});
    c.push_back({"VdbIsDirectory", "VDB", vdb([](const fs::path& f) {
                     fs::remove(f);
                     fs::create_directory(f);
                 }), 3, {"/media/tissue/volume/file", "grid.vdb", "is a folder"}});
    c.push_back({"VdbMissingGrid", "VDB", vdb([](const fs::path&) {}, "mus"), 2,
                 {"/media/tissue/volume/scattering_grid", "no grid named \"mus\"", "\"density\""}});
    c.push_back({"VdbNaNVoxel", "VDB", vdb([](const fs::path& f) {
                     writeVoxelGrids(f.string(), Affine::scaling(1.0),
                                     {{"density", {{0, 0, 0}, {7, 7, 7}}, [](int i, int, int) { return i == 3 ? std::nan("") : 1.0; }, {}}});
                 }), 2, {"/media/tissue/volume/scattering_grid", "grid \"density\"", "nan", "(3, "}});
    c.push_back({"VdbNegativeVoxel", "VDB", vdb([](const fs::path& f) {
                     writeVoxelGrids(f.string(), Affine::scaling(1.0),
                                     {{"density", {{0, 0, 0}, {7, 7, 7}}, [](int, int j, int) { return j == 2 ? -4.0 : 1.0; }, {}}});
                 }), 2, {"grid \"density\"", "-4"}});
    // ---- SWC files (voxelize) ----
    c.push_back({"SwcSixFields", "SWC", swc("1 1 0 0 0 5\n"), 2, {"cell.swc:1", "expected 7 fields", "1 1 0 0 0 5"}});
    c.push_back({"SwcNaNCoordinate", "SWC", swc("1 1 nan 0 0 5 -1\n"), 2, {"cell.swc:1", "\"x\"", "nan"}});
    c.push_back({"SwcInfiniteRadius", "SWC", swc("1 1 0 0 0 inf -1\n"), 2, {"cell.swc:1", "\"radius\"", "inf"}});
    c.push_back({"SwcNegativeRadius", "SWC", swc("1 1 0 0 0 -5 -1\n"), 2, {"cell.swc:1", "\"radius\"", "-5"}});
    c.push_back({"SwcIdBeyondInt", "SWC", swc("99999999999 1 0 0 0 5 -1\n"), 2, {"cell.swc:1", "\"id\"", "99999999999"}});
    c.push_back({"SwcCycle", "SWC", swc("1 1 0 0 0 5 2\n2 3 10 0 0 1 1\n"), 2, {"cell.swc", "\"parent\"", "cycle"}});
    c.push_back({"SwcUnknownParent", "SWC", swc("1 1 0 0 0 5 -1\n2 3 10 0 0 1 7\n"), 2, {"cell.swc:2", "\"parent\"", "7"}});
    c.push_back({"SwcEmpty", "SWC", swc("# only a comment\n"), 2, {"cell.swc", "no samples"}});
    c.push_back({"SwcHugeField", "SWC", swcText([] { return "1 1 " + std::string(10 << 20, '9') + "x 0 0 5 -1\n"; }), 2, {"cell.swc:1", "\"x\"", "characters"}});
    c.push_back({"SwcIsDirectory", "SWC", [](const TempDir& dir) {
                     fs::create_directory(dir.file("cell.swc"));
                     return std::vector<std::string>{"voxelize", dir.file("cell.swc").string(), "--dye", "AF488", "--concentration", "10uM", "--voxel",
                                                     "1um", "-o", dir.file("out.vdb").string()};
                 }, 3, {"cell.swc", "is a folder"}});
    c.push_back({"SwcIsDevZero", "SWC", cli({"voxelize", "/dev/zero", "--dye", "AF488", "--concentration", "10uM", "--voxel", "1um", "-o",
                                             "{dir}/out.vdb"}), 3, {"/dev/zero", "not a regular file"}});
    c.push_back({"MeshIsDevZero", "mesh", [](const TempDir& dir) {
                     return render(dir.write("scene.json", meshScene("/dev/zero").dump()), dir);
                 }, 3, {"/shapes/1/file", "/dev/zero", "not a regular file"}});
    c.push_back({"SwcOneKilometreNeurite", "SWC", swc(swcLine(1, 3, 0, 0, 0, 0.1, -1) + swcLine(2, 3, 1e9, 0, 0, 0.1, 1)), 2,
                 {"voxel size", "cell.swc", "memory cap of 512 MiB"}});
    c.push_back({"VoxelTwoHundredthMicronOnSample", "SWC", voxelizeSample({"--voxel", "0.02um"}), 2,
                 {"C231296A-P3.CNG.swc", "voxel size", "0.02 um", "memory cap"}});
    c.push_back({"VoxelOneNanoMicron", "SWC", voxelizeSample({"--voxel", "1e-9um"}), 2, {"C231296A-P3.CNG.swc", "1e-09 um", "2e9"}});
    // ---- command-line values ----
    c.push_back({"VoxelZero", "CLI", voxelizeSample({"--voxel", "0um"}), 2, {"--voxel", "0um"}});
    c.push_back({"VoxelNaN", "CLI", voxelizeSample({"--voxel", "nan um"}), 2, {"--voxel", "nan um"}});
    c.push_back({"VoxelizeSupersamplingZero", "CLI", voxelizeSample({"--voxel", "1um", "--supersampling", "0"}), 2, {"supersampling", "0"}});
    c.push_back({"VoxelizeThreads65537", "CLI", voxelizeSample({"--voxel", "1um", "--threads", "65537"}), 2, {"--threads", "65537"}});
    c.push_back({"VoxelizeOutputInProc", "CLI", cli({"voxelize", (kSource / "samples/neurons/C231296A-P3.CNG.swc").string(), "--dye", "AF488",
                                                     "--concentration", "10uM", "--voxel", "1um", "-o", "/proc/out.vdb"}), 3,
                 {"/proc/out.vdb", "not writable"}});
    c.push_back({"VoxelizeOutputIsDirectory", "CLI", [](const TempDir& dir) {
                     fs::create_directory(dir.file("sub.vdb"));
                     return std::vector<std::string>{"voxelize", (kSource / "samples/neurons/C231296A-P3.CNG.swc").string(), "--dye", "AF488",
                                                     "--concentration", "10uM", "--voxel", "1um", "-o", dir.file("sub.vdb").string()};
                 }, 3, {"sub.vdb", "is a folder"}});
    c.push_back({"RenderSppZero", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.exr", "--spp", "0"}), 2, {"--spp", "0"}});
    c.push_back({"RenderSppTwoToThe63", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.exr", "--spp", "9223372036854775808"}), 2,
                 {"--spp", "9223372036854775808"}});
    c.push_back({"RenderSpp1e9", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.exr", "--spp", "1e9"}), 2, {"--spp", "1e9"}});
    c.push_back({"RenderSeedMinusOne", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.exr", "--seed", "-1"}), 2, {"--seed", "-1"}});
    c.push_back({"RenderSeedTwoToThe64", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.exr", "--seed", "18446744073709551616"}), 2,
                 {"--seed", "18446744073709551616"}});
    c.push_back({"RenderThreads65537", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.exr", "--threads", "65537"}), 2,
                 {"--threads", "65537"}});
    c.push_back({"RenderThreadsNegative", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.exr", "--threads", "-1"}), 2, {"--threads", "-1"}});
    c.push_back({"RenderCheckpointNaN", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.exr", "--checkpoint-seconds", "nan"}), 2,
                 {"--checkpoint-seconds", "nan"}});
    c.push_back({"RenderOutputInProc", "CLI", cli({"render", "{scene}", "-o", "/proc/out.exr"}), 3, {"/proc/out.exr", "not writable"}});
    c.push_back({"RenderOutputIsDirectory", "CLI", [](const TempDir& dir) {
                     fs::create_directory(dir.file("out.exr"));
                     return std::vector<std::string>{"render", dir.write("scene.json", baseScene().dump()).string(), "-o",
                                                     dir.file("out.exr").string()};
                 }, 3, {"out.exr", "is a folder"}});
    c.push_back({"RenderOutputNotExr", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.png"}), 2, {"out.png", ".exr"}});
    c.push_back({"RenderUnknownModel", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.exr", "--fluorescence", std::string(100000, 'q')}), 2,
                 {"--fluorescence", "qqqq", "100000 characters"}});
    c.push_back({"RenderResumeWithoutCheckpoint", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.exr", "--resume"}), 3,
                 {"out.exr.checkpoint", "no checkpoint"}});
    c.push_back({"RenderResumeDamagedCheckpoint", "CLI", [](const TempDir& dir) {
                     dir.write("out.exr.checkpoint", "FLUOROSIM-CKPT" + std::string(100, '\0'));
                     return std::vector<std::string>{"render", dir.write("scene.json", baseScene().dump()).string(), "-o",
                                                     dir.file("out.exr").string(), "--resume"};
                 }, 3, {"out.exr.checkpoint", "damaged"}});
    c.push_back({"MemoryCapMalformed", "CLI", cli({"render", "{scene}", "-o", "{dir}/out.exr", "--memory-cap", "lots"}), 2,
                 {"--memory-cap", "lots"}});
    c.push_back({"SlabPhotons1e30", "CLI", cli({"validate", "slab", "--thickness", "1", "--photons", "1e30", "--quiet"}), 2,
                 {"--photons", "1e+30"}});
    c.push_back({"SlabThicknessOverflow", "CLI", cli({"validate", "slab", "--thickness", "1e308 m", "--quiet"}), 2,
                 {"--thickness", "1e308 m", "not finite"}});
    c.push_back({"SlabSeedMinusOne", "CLI", cli({"validate", "slab", "--thickness", "1", "--seed", "-1", "--quiet"}), 2, {"--seed", "-1"}});
    c.push_back({"SlabThreads65537", "CLI", cli({"validate", "slab", "--thickness", "1", "--threads", "65537", "--quiet"}), 2,
                 {"--threads", "65537"}});
    c.push_back({"EmissionOutputMissingFolder", "CLI", cli({"validate", "emission", "--dye", "AF488", "--excitation", "495", "-o",
                                                            "{dir}/none/e.json"}), 3, {"{dir}/none", "does not exist"}});
    c.push_back({"SweepThreads65537", "CLI", cli({"validate", "sweep", "--dye", "AF488", "--threads", "65537", "-o", "{dir}/s.json"}), 2,
                 {"--threads", "65537"}});
    c.push_back({"SweepOutputIsDirectory", "CLI", cli({"validate", "sweep", "--dye", "AF488", "-o", "{dir}"}), 3, {"is a folder"}});
    c.push_back({"EmissionSppZero", "CLI", cli({"validate", "emission", "--dye", "AF488", "--excitation", "495", "--spp", "0", "-o",
                                                "{dir}/e.json"}), 2, {"--spp", "0"}});
    c.push_back({"LightSheetPositions1e9", "CLI", cli({"validate", "lightsheet", "--wavelength", "488", "--waist", "2", "--positions", "1e9",
                                                       "-o", "{dir}/s.json"}), 2, {"--positions", "1e9"}});
    return c;
}

// gtest prints parameters in failure messages; the name is enough.
void PrintTo(const Case& c, std::ostream* os) { *os << c.name; }

std::string excerptForLog(const std::string& s) { return s.size() > 2000 ? s.substr(0, 2000) + "..." : s; }

class BadInput : public ::testing::TestWithParam<Case> {
protected:
    void SetUp() override { ::setenv("FLUOROSIM_MEMORY_CAP", kCap, 1); }
};

TEST_P(BadInput, OneLineErrorNamingFieldAndValue) {
    const Case& c = GetParam();
    const TempDir dir;
    const std::vector<std::string> args = c.args(dir);
    const testing::RunResult r = testing::runCli(dir, args, 60);
    // In the XML report (--gtest_output=xml), from which docs/reliability.md tabulates the cases.
    RecordProperty("input", c.input);
    std::string command;
    for (const std::string& a : args) command += (command.empty() ? "" : " ") + excerptForLog(a).substr(0, 120);
    RecordProperty("command", command);
    RecordProperty("folder", dir.path().string());
    RecordProperty("exit_code", r.exitCode);
    RecordProperty("message", excerptForLog(r.err));
    RecordProperty("peak_rss_mib", static_cast<int>(r.maxRssKb / 1024));
    EXPECT_NE(r.exitCode, 124) << "timed out (a hang)";
    EXPECT_EQ(r.exitCode, c.exitCode) << "stderr: " << excerptForLog(r.err);
    ASSERT_LT(r.err.size(), 2500u) << "the message echoes too much input: " << excerptForLog(r.err);
    std::vector<std::string> parts;
    for (std::string m : c.mentions) {
        for (size_t p; (p = m.find("{dir}")) != std::string::npos;) m.replace(p, 5, dir.path().string());
        parts.push_back(m);
    }
    testing::expectOneLineError(r, parts);
    if (kMeasureMemory) {
        EXPECT_LT(r.maxRssKb, kCapKb + kBaselineKb) << "peak memory beyond the cap";
    }
    EXPECT_TRUE(r.out.empty()) << excerptForLog(r.out);
}

INSTANTIATE_TEST_SUITE_P(Matrix, BadInput, ::testing::ValuesIn(cases()),
                         [](const ::testing::TestParamInfo<Case>& p) { return p.param.name; });

}  // namespace
}  // namespace fluorosim
