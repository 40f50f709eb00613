// The fluorosim command line: exit codes (2 ConfigError, 3 IoError) and one-line error messages on
// stderr that name the problem, run through the built binary.
#include <gtest/gtest.h>

#include "support/cli_runner.h"
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "io/image_io.h"

namespace fluorosim {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace testing;

std::string sceneJson(int width, int height, int spp) {
    json j = json::parse(R"({
      "fluorosim_scene": 1,
      "spectral": {"range": ["400 nm", "700 nm"], "bin_width": "50 nm"},
      "render": {"seed": 1},
      "camera": {"position": ["0 mm", "50 mm", "-200 mm"], "look_at": ["0 mm", "50 mm", "0 mm"], "fov_y_deg": 40},
      "materials": {"white": {"type": "diffuse", "reflectance": 0.7}},
      "shapes": [
        {"type": "quad", "name": "floor", "origin": ["-100 mm", "0 mm", "-100 mm"], "edge1": ["200 mm", "0 mm", "0 mm"],
         "edge2": ["0 mm", "0 mm", "200 mm"], "material": "white"},
        {"type": "sphere", "name": "ball", "center": ["0 mm", "30 mm", "0 mm"], "radius": "30 mm", "material": "white"},
        {"type": "quad", "name": "light", "origin": ["-20 mm", "120 mm", "-20 mm"], "edge1": ["40 mm", "0 mm", "0 mm"],
         "edge2": ["0 mm", "0 mm", "40 mm"], "emission": {"radiance": {"reference": "illuminant:D65", "scale": 0.1}, "two_sided": true}}
      ]
    })");
    j["camera"]["resolution"] = {width, height};
    j["render"]["spp"] = spp;
    return j.dump(2);
}

// ---- render ----

TEST(Cli, RenderMissingSceneFile) {
    const TempDir dir;
    const std::string scene = (dir.path() / "no_such_scene.json").string();
    const auto r = runCli(dir, {"render", scene, "-o", (dir.path() / "out.exr").string()});
    EXPECT_EQ(r.exitCode, 3);
    expectOneLineError(r, {scene});
}

TEST(Cli, RenderToMissingOutputFolderFailsBeforeRendering) {
    const TempDir dir;
    // A scene that would take hours to render: the check must come first. The 60 s limit is not a
    // speed measurement: a render that started first would still be running when it expires.
    const auto scene = dir.write("big.json", sceneJson(1024, 1024, 1 << 20));
    const fs::path folder = dir.path() / "no_such_folder";
    const auto r = runCli(dir, {"render", scene.string(), "-o", (folder / "out.exr").string(), "--threads", "1"}, 60);
    EXPECT_EQ(r.exitCode, 3);
    EXPECT_NE(r.exitCode, 124) << "timed out: it rendered before checking the output folder";
    expectOneLineError(r, {folder.string()});
    EXPECT_FALSE(fs::exists(folder));
}

TEST(Cli, RenderToNonExrOutput) {
    const TempDir dir;
    // As above: a render of hours, so only a check made before rendering ends within the limit.
    const auto scene = dir.write("scene.json", sceneJson(1024, 1024, 1 << 20));
    const std::string out = (dir.path() / "out.png").string();
    const auto r = runCli(dir, {"render", scene.string(), "-o", out, "--threads", "1"}, 60);
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {out, ".exr"});
    EXPECT_FALSE(fs::exists(out));
}

TEST(Cli, RenderMalformedScene) {
    const TempDir dir;
    const auto scene = dir.write("broken.json", "{\n  \"fluorosim_scene\": 1,\n  \"shapes\": [,]\n}\n");
    const auto r = runCli(dir, {"render", scene.string(), "-o", (dir.path() / "out.exr").string()});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {scene.string()});
}

TEST(Cli, RenderInvalidSceneNamesFieldAndValue) {
    const TempDir dir;
    json j = json::parse(sceneJson(8, 8, 2));
    j["shapes"][1]["radius"] = "0 mm";
    const auto scene = dir.write("bad_radius.json", j.dump());
    const auto r = runCli(dir, {"render", scene.string(), "-o", (dir.path() / "out.exr").string()});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {scene.string(), "/shapes/1/radius", "0 mm"});
}

TEST(Cli, RenderSppZero) {
    const TempDir dir;
    const auto scene = dir.write("scene.json", sceneJson(8, 8, 2));
    const auto r = runCli(dir, {"render", scene.string(), "-o", (dir.path() / "out.exr").string(), "--spp", "0"});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"--spp", "0"});
    EXPECT_FALSE(fs::exists(dir.path() / "out.exr"));
}

TEST(Cli, RenderSppNegative) {
    const TempDir dir;
    const auto scene = dir.write("scene.json", sceneJson(8, 8, 2));
    const auto r = runCli(dir, {"render", scene.string(), "-o", (dir.path() / "out.exr").string(), "--spp", "-3"});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"--spp", "-3"});
    EXPECT_FALSE(fs::exists(dir.path() / "out.exr"));
}

TEST(Cli, RenderSppMinusOneIsRejectedToo) {
    // -1 must not act as a hidden "use the scene's spp" sentinel.
    const TempDir dir;
    const auto scene = dir.write("scene.json", sceneJson(8, 8, 2));
    const auto r = runCli(dir, {"render", scene.string(), "-o", (dir.path() / "out.exr").string(), "--spp", "-1", "--threads", "1"});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"--spp", "-1"});
    EXPECT_FALSE(fs::exists(dir.path() / "out.exr"));
}

TEST(Cli, TinyRenderWritesExrAndPng) {
    const TempDir dir;
    const auto scene = dir.write("scene.json", sceneJson(8, 8, 16));
    const fs::path out = dir.path() / "tiny.exr";
    const auto r = runCli(dir, {"render", scene.string(), "-o", out.string(), "--spp", "2", "--threads", "1", "--seed", "5"});
    ASSERT_EQ(r.exitCode, 0) << "stderr:\n" << r.err;
    ASSERT_TRUE(fs::exists(out));
    EXPECT_GT(fs::file_size(out), 0u);
    const fs::path png = dir.path() / "tiny.png";
    ASSERT_TRUE(fs::exists(png));
    EXPECT_GT(fs::file_size(png), 0u);
    EXPECT_FALSE(fs::exists(out.string() + ".partial.exr"));
    // stdout is one JSON summary.
    const auto summary = json::parse(r.out);
    EXPECT_EQ(summary.at("spp").get<int>(), 2);
    EXPECT_EQ(summary.at("image").get<std::string>(), out.string());
    EXPECT_EQ(summary.at("cancelled").get<bool>(), false);
    // No stray write-probe files are left in the output folder.
    for (const auto& e : fs::directory_iterator(dir.path()))
        EXPECT_FALSE(contains(e.path().filename().string(), "write-test")) << e.path();
}

// Starts a render of `scene` in the background, waits until it has written its checkpoint (so at least
// one pass is finished and the signal handlers are installed), sends `signal` and waits for the exit.
// Returns the exit code. The wait is for a file, not for time; its 120 s limit fails the test only
// if the render never writes a checkpoint.
int interruptAfterCheckpoint(const TempDir& dir, const fs::path& scene, const fs::path& out, const char* signal) {
    const fs::path rc = dir.path() / "rc.txt", ckpt = out.string() + ".checkpoint";
    const std::string cmd =
        "bash -c " + quote(quote(FLUOROSIM_CLI) + " render " + quote(scene.string()) + " -o " + quote(out.string()) +
                           " --threads 2 --checkpoint-seconds 0.001 </dev/null >" + quote((dir.path() / "out.txt").string()) + " 2>" +
                           quote((dir.path() / "err.txt").string()) + " & pid=$!; for i in $(seq 2400); do [ -e " + quote(ckpt.string()) +
                           " ] && break; sleep 0.05; done; kill -" + signal + " $pid; wait $pid; echo $? > " + quote(rc.string()));
    if (std::system(cmd.c_str()) != 0) return -1;
    return std::stoi(readFile(rc));
}

bool sameChannels(const fs::path& a, const fs::path& b) {
    const ExrChannels ea = readExr(a.string()), eb = readExr(b.string());
    if (ea.channels.size() != eb.channels.size() || ea.channels.size() < 4) return false;
    for (const auto& [name, values] : ea.channels)
        if (!eb.channels.count(name) || values != eb.channels.at(name)) return false;
    return true;
}

TEST(Cli, InterruptedRenderKeepsFinishedPassesAndResumesToTheSameImage) {
    const TempDir dir;
    const auto scene = dir.write("scene.json", sceneJson(24, 16, 1000000));
    const fs::path out = dir.path() / "long.exr", ckpt = dir.path() / "long.exr.checkpoint";
    ASSERT_EQ(interruptAfterCheckpoint(dir, scene, out, "TERM"), 130) << readFile(dir.path() / "err.txt");
    const std::string err = readFile(dir.path() / "err.txt");
    EXPECT_TRUE(contains(err, "interrupted")) << err;
    // The finished passes are in files their readers open; the summary and the EXR agree on them.
    const json summary = json::parse(readFile(dir.path() / "out.txt"));
    EXPECT_TRUE(summary.at("cancelled").get<bool>());
    const int done = summary.at("spp").get<int>();
    ASSERT_GE(done, 1);
    const ExrChannels image = readExr(out.string());
    EXPECT_EQ(image.attributes.at("fluorosim.spp"), std::to_string(done));
    EXPECT_TRUE(fs::exists(dir.path() / "long.png"));
    EXPECT_TRUE(fs::exists(ckpt));
    for (const auto& e : fs::directory_iterator(dir.path())) EXPECT_FALSE(contains(e.path().string(), ".partial")) << e.path();

    // A checkpoint of another seed or another scene is refused, and kept.
    const auto seed = runCli(dir, {"render", scene.string(), "-o", out.string(), "--resume", "--seed", "2"});
    EXPECT_EQ(seed.exitCode, 2);
    expectOneLineError(seed, {"--seed", "seed 1", "2", ckpt.string()});
    json changed = json::parse(readFile(scene));
    changed["camera"]["fov_y_deg"] = 41;
    const auto other = dir.write("other.json", changed.dump());
    const auto otherRun = runCli(dir, {"render", other.string(), "-o", out.string(), "--resume"});
    EXPECT_EQ(otherRun.exitCode, 2);
    expectOneLineError(otherRun, {other.string(), "differs from the scene", ckpt.string()});
    ASSERT_TRUE(fs::exists(ckpt));

    // Resumed to a few more samples, on another thread count: the same image as one uninterrupted run.
    const std::string target = std::to_string(done + 3);
    const auto resumed = runCli(dir, {"render", scene.string(), "-o", out.string(), "--resume", "--spp", target, "--threads", "1"});
    ASSERT_EQ(resumed.exitCode, 0) << resumed.err;
    EXPECT_TRUE(contains(resumed.err, "resuming")) << resumed.err;
    EXPECT_EQ(json::parse(resumed.out).at("spp").get<int>(), done + 3);
    EXPECT_FALSE(fs::exists(ckpt)) << "a finished render removes its checkpoint";
    const fs::path reference = dir.path() / "reference.exr";
    const auto refRun = runCli(dir, {"render", scene.string(), "-o", reference.string(), "--spp", target, "--threads", "2"});
    ASSERT_EQ(refRun.exitCode, 0) << refRun.err;
    EXPECT_TRUE(sameChannels(out, reference));
    // The summaries agree too: the checkpoint carried the path statistics of the first run.
    const json ref = json::parse(refRun.out);
    EXPECT_EQ(json::parse(resumed.out).at("paths"), ref.at("paths"));
    EXPECT_EQ(json::parse(resumed.out).at("scattering_events"), ref.at("scattering_events"));
}

// --time renders finished passes until the budget is spent: the image is that of a render of the spp
// it reached, and the checkpoint stays so that --resume continues it.
TEST(Cli, TimedRenderStopsAtAFinishedPassAndEqualsARenderOfItsSpp) {
    const TempDir dir;
    const auto scene = dir.write("scene.json", sceneJson(24, 16, 4));  // the scene's spp does not stop a timed render
    const fs::path out = dir.path() / "timed.exr";
    const auto timed = runCli(dir, {"render", scene.string(), "-o", out.string(), "--time", "0.5", "--threads", "2"});
    ASSERT_EQ(timed.exitCode, 0) << timed.err;
    const json summary = json::parse(timed.out);
    EXPECT_TRUE(summary.at("time_budget_spent").get<bool>());
    EXPECT_EQ(summary.at("time_budget_seconds").get<double>(), 0.5);
    EXPECT_FALSE(summary.at("cancelled").get<bool>());
    const int done = summary.at("spp").get<int>();
    EXPECT_GT(done, 4);
    EXPECT_EQ(readExr(out.string()).attributes.at("fluorosim.spp"), std::to_string(done));
    EXPECT_TRUE(fs::exists(out.string() + ".checkpoint"));
    EXPECT_TRUE(contains(timed.err, "--resume continues it")) << timed.err;
    // Its checkpoint is refused to a resume with another integrator, and kept.
    const auto other = runCli(dir, {"render", scene.string(), "-o", out.string(), "--resume", "--time", "0.5", "--integrator", "mnee"});
    EXPECT_EQ(other.exitCode, 2);
    expectOneLineError(other, {"--integrator", out.string() + ".checkpoint", "\"path\"", "\"mnee\""});
    EXPECT_TRUE(fs::exists(out.string() + ".checkpoint"));
    const fs::path reference = dir.path() / "reference.exr";
    const auto refRun = runCli(dir, {"render", scene.string(), "-o", reference.string(), "--spp", std::to_string(done), "--threads", "1"});
    ASSERT_EQ(refRun.exitCode, 0) << refRun.err;
    EXPECT_TRUE(sameChannels(out, reference));

    for (const char* bad : {"0", "-1", "nan", "2e9"}) {
        const auto r = runCli(dir, {"render", scene.string(), "-o", (dir.path() / "bad.exr").string(), "--time", bad});
        EXPECT_EQ(r.exitCode, 2) << bad;
        expectOneLineError(r, {"--time", "must lie in (0, 1e9] seconds"});
    }
}

TEST(Cli, UnknownIntegratorIsRefusedFromTheCommandLineAndTheScene) {
    const TempDir dir;
    const auto scene = dir.write("scene.json", sceneJson(8, 8, 1));
    const auto r = runCli(dir, {"render", scene.string(), "-o", (dir.path() / "o.exr").string(), "--integrator", "bdpt"});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"--integrator", "path, mnee or light", "bdpt"});
    json j = json::parse(readFile(scene));
    j["render"]["integrator"] = "photons";
    const auto bad = dir.write("bad.json", j.dump());
    const auto b = runCli(dir, {"render", bad.string(), "-o", (dir.path() / "o.exr").string()});
    EXPECT_EQ(b.exitCode, 2);
    expectOneLineError(b, {bad.string(), "/render/integrator", "mnee"});
    // A valid choice renders, and the summary says which.
    const auto ok = runCli(dir, {"render", scene.string(), "-o", (dir.path() / "o.exr").string(), "--integrator", "mnee"});
    ASSERT_EQ(ok.exitCode, 0) << ok.err;
    EXPECT_EQ(json::parse(ok.out).at("integrator").get<std::string>(), "mnee");
    // Photons per pixel are checked where the scene gives them.
    j = json::parse(readFile(scene));
    j["render"]["photons_per_pixel"] = 0;
    const auto zero = dir.write("zero.json", j.dump());
    const auto z = runCli(dir, {"render", zero.string(), "-o", (dir.path() / "o.exr").string()});
    EXPECT_EQ(z.exitCode, 2);
    expectOneLineError(z, {zero.string(), "/render/photons_per_pixel", "got 0"});
    // So is the merging radius.
    j["render"]["photons_per_pixel"] = 1;
    j["render"]["merge_radius_pixels"] = -1;
    const auto negative = dir.write("negative.json", j.dump());
    const auto n = runCli(dir, {"render", negative.string(), "-o", (dir.path() / "o.exr").string()});
    EXPECT_EQ(n.exitCode, 2);
    expectOneLineError(n, {negative.string(), "/render/merge_radius_pixels", "-1"});
}

TEST(Cli, InterruptBySigintIsHandledLikeSigterm) {
    const TempDir dir;
    const auto scene = dir.write("scene.json", sceneJson(24, 16, 1000000));
    const fs::path out = dir.path() / "long.exr";
    ASSERT_EQ(interruptAfterCheckpoint(dir, scene, out, "INT"), 130) << readFile(dir.path() / "err.txt");
    EXPECT_GE(readExr(out.string()).width, 24);
    EXPECT_TRUE(fs::exists(out.string() + ".checkpoint"));
}

TEST(Cli, RenderIsIdenticalOnOneAndTwoThreads) {
    const TempDir dir;
    const auto scene = dir.write("scene.json", sceneJson(16, 12, 4));
    const fs::path a = dir.path() / "a.exr", b = dir.path() / "b.exr";
    ASSERT_EQ(runCli(dir, {"render", scene.string(), "-o", a.string(), "--threads", "1", "--seed", "9"}).exitCode, 0);
    ASSERT_EQ(runCli(dir, {"render", scene.string(), "-o", b.string(), "--threads", "2", "--seed", "9"}).exitCode, 0);
    const ExrChannels ea = readExr(a.string()), eb = readExr(b.string());
    ASSERT_EQ(ea.channels.size(), eb.channels.size());
    EXPECT_GT(ea.channels.size(), 3u);  // R, G, B and spectral channels
    for (const auto& [name, values] : ea.channels) EXPECT_EQ(values, eb.channels.at(name)) << name;
}

// ---- validate slab ----

const std::vector<std::string> kSlabBase = {"validate", "slab", "--photons", "1e4", "--quiet", "--threads", "1"};

std::vector<std::string> slabArgs(std::initializer_list<std::string> extra) {
    std::vector<std::string> a = kSlabBase;
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
}

void expectSlabRejected(const std::vector<std::string>& args, const std::string& option, const std::string& value) {
    SCOPED_TRACE(option + " " + value);
    const TempDir dir;
    const auto r = runCli(dir, args);
    EXPECT_NE(r.exitCode, 0);
    EXPECT_LT(r.exitCode, 124) << "crashed or timed out";
    expectOneLineError(r, {option, value});
    EXPECT_TRUE(r.out.empty()) << r.out;
}

TEST(Cli, SlabRejectsAnisotropyOne) {
    expectSlabRejected(slabArgs({"--thickness", "0.1", "--mus", "10", "--g", "1.0"}), "--g", "1.0");
}

TEST(Cli, SlabRejectsAnisotropyNan) {
    expectSlabRejected(slabArgs({"--thickness", "0.1", "--mus", "10", "--g", "nan"}), "--g", "nan");
}

TEST(Cli, SlabRejectsNegativeAbsorption) {
    expectSlabRejected(slabArgs({"--thickness", "0.1", "--mua", "-1"}), "--mua", "-1");
}

TEST(Cli, SlabRejectsZeroThickness) {
    expectSlabRejected(slabArgs({"--thickness", "0"}), "--thickness", "0");
}

TEST(Cli, SlabRejectsIndexBelowOne) {
    expectSlabRejected(slabArgs({"--thickness", "0.1", "--n", "0.5"}), "--n", "0.5");
}

TEST(Cli, SlabRejectsSinglePhoton) {
    expectSlabRejected({"validate", "slab", "--thickness", "0.1", "--quiet", "--photons", "1"}, "--photons", "1");
}

TEST(Cli, SlabRejectsCoefficientWithWrongUnit) {
    expectSlabRejected(slabArgs({"--thickness", "0.1", "--mua", "5 mm"}), "--mua", "5 mm");
}

TEST(Cli, SlabJsonHasTheDocumentedKeys) {
    const TempDir dir;
    const auto r = runCli(dir, slabArgs({"--mua", "1", "--mus", "100", "--g", "0.9", "--thickness", "0.1", "--seed", "3"}));
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_TRUE(r.err.empty()) << "--quiet still wrote:\n" << r.err;
    const auto j = json::parse(r.out);
    for (const char* key : {"Rd", "Tt", "Rd_stderr", "Tt_stderr", "Rsp", "photons", "seconds"}) {
        ASSERT_TRUE(j.contains(key)) << key << " missing in " << r.out;
        EXPECT_TRUE(j.at(key).is_number()) << key;
    }
    EXPECT_EQ(j.at("photons").get<uint64_t>(), 10000u);
    const double rd = j.at("Rd").get<double>(), tt = j.at("Tt").get<double>();
    EXPECT_GT(rd, 0.0);
    EXPECT_GT(tt, 0.0);
    EXPECT_LE(rd + tt + j.at("Rsp").get<double>(), 1.0 + 1e-9);
    EXPECT_GT(j.at("Rd_stderr").get<double>(), 0.0);
    EXPECT_LT(j.at("Rd_stderr").get<double>(), 0.05);
    EXPECT_GE(j.at("seconds").get<double>(), 0.0);
}

TEST(Cli, SlabUnitsGiveBitIdenticalResults) {
    const TempDir dir;
    const auto withUnits = runCli(dir, slabArgs({"--mua", "9/mm", "--mus", "0.9/mm", "--thickness", "0.2mm", "--seed", "11"}));
    ASSERT_EQ(withUnits.exitCode, 0) << withUnits.err;
    const auto bare = runCli(dir, slabArgs({"--mua", "90", "--mus", "9", "--thickness", "0.02", "--seed", "11"}));
    ASSERT_EQ(bare.exitCode, 0) << bare.err;
    auto a = json::parse(withUnits.out), b = json::parse(bare.out);
    for (const char* key : {"Rd", "Tt", "Rd_stderr", "Tt_stderr", "Rsp", "Ta", "Tt_ballistic", "photons"})
        EXPECT_EQ(a.at(key), b.at(key)) << key << "\nunits: " << withUnits.out << "\nbare:  " << bare.out;
    EXPECT_EQ(a.at("input"), b.at("input"));
    EXPECT_GT(a.at("Rd").get<double>(), 0.0);
    EXPECT_DOUBLE_EQ(a.at("input").at("mua_per_cm").get<double>(), 90.0);
    EXPECT_DOUBLE_EQ(a.at("input").at("thickness_cm").get<double>(), 0.02);
}

TEST(Cli, NoSubcommandIsAParseError) {
    const TempDir dir;
    const auto r = runCli(dir, {});
    EXPECT_NE(r.exitCode, 0);
    EXPECT_LT(r.exitCode, 124);
}

}  // namespace
}  // namespace fluorosim

namespace fluorosim {
namespace {

TEST(Cli, ValidateEmissionWritesSpectraAndRejectsBadInput) {
    const TempDir dir;
    const fs::path out = dir.path() / "emission.json";
    const auto r = runCli(dir, {"validate", "emission", "--dye", "AF488", "--excitation", "495", "--spp", "256", "--seed", "3", "-o", out.string()});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    std::ifstream f(out);
    const json j = json::parse(f);
    const auto n = j.at("wavelength_nm").size();
    EXPECT_GT(n, 100u);
    EXPECT_EQ(j.at("rendered").size(), n);
    EXPECT_EQ(j.at("reference").size(), n);
    EXPECT_GT(j.at("pearson").get<double>(), 0.8);  // 256 spp is noisy; docs/validation.md has the full runs
    EXPECT_NEAR(j.at("reference_peak_nm").get<double>(), 519.5, 1.0);

    const auto unknown = runCli(dir, {"validate", "emission", "--dye", "AF489", "--excitation", "495", "-o", out.string()});
    EXPECT_EQ(unknown.exitCode, 2);
    EXPECT_TRUE(contains(unknown.err, "alexa_fluor_488")) << unknown.err;
    const auto negative = runCli(dir, {"validate", "emission", "--dye", "AF488", "--excitation", "495", "--concentration", "-1uM", "-o", out.string()});
    EXPECT_EQ(negative.exitCode, 2);
    EXPECT_TRUE(contains(negative.err, "--concentration")) << negative.err;
    const auto massNoMolar = runCli(dir, {"validate", "sweep", "--dye", "AF488", "--concentration", "1 g/L", "-o", out.string()});
    EXPECT_EQ(massNoMolar.exitCode, 2);
    EXPECT_TRUE(contains(massNoMolar.err, "--concentration")) << massNoMolar.err;
}

}  // namespace
}  // namespace fluorosim

namespace fluorosim {
namespace {

// A dyed scene's EXR carries elastic and fluorescent layers (RGB and spectral) that add up to the
// main image; a scene without dyes carries none.
TEST(Cli, FluorescentSceneWritesElasticAndFluorescentLayers) {
    const TempDir dir;
    const auto scene = dir.write("dyed.json", R"({
      "fluorosim_scene": 1,
      "spectral": {"range": ["450 nm", "700 nm"], "bin_width": "10 nm"},
      "camera": {"position": ["0 mm", "0 mm", "-5 mm"], "look_at": ["0 mm", "0 mm", "0 mm"], "up": [0, 1, 0], "fov_y_deg": 30, "resolution": [6, 6]},
      "media": {"dyed": {"sigma_s": "5 /mm", "dyes": [{"dye": "AF488", "concentration": "50 uM"}]}},
      "shapes": [{"type": "sphere", "name": "ball", "center": ["0 mm", "0 mm", "0 mm"], "radius": "1 mm", "interior": "dyed"}],
      "lights": [{"type": "point", "position": ["0 mm", "5 mm", "0 mm"], "intensity": {"lines": [{"wavelength": "488 nm", "power": 1}]}}]
    })");
    const fs::path out = dir.path() / "dyed.exr";
    const auto r = runCli(dir, {"render", scene.string(), "-o", out.string(), "--spp", "16", "--threads", "1"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const ExrChannels e = readExr(out.string());
    for (const char* c : {"R", "G", "B"}) {
        ASSERT_TRUE(e.channels.count(std::string("elastic.") + c));
        ASSERT_TRUE(e.channels.count(std::string("fluorescent.") + c));
        const auto& total = e.channels.at(c);
        const auto& el = e.channels.at(std::string("elastic.") + c);
        const auto& fl = e.channels.at(std::string("fluorescent.") + c);
        double fluorescentSum = 0;
        for (size_t i = 0; i < total.size(); ++i) {
            EXPECT_NEAR(total[i], el[i] + fl[i], 1e-5 * (1 + std::abs(total[i])));
            fluorescentSum += fl[i];
        }
        if (std::string(c) == "G") {
            EXPECT_GT(fluorescentSum, 0.0);  // AF488 emits green
        }
    }
    EXPECT_TRUE(e.channels.count("fluorescent.S0.525,000000nm"));
    EXPECT_TRUE(e.channels.count("elastic.S0.485,000000nm"));
    const auto summary = json::parse(r.out);
    EXPECT_EQ(summary.at("fluorescence").get<std::string>(), "full");
    EXPECT_GT(summary.at("fluorescence_branches").get<uint64_t>(), 0u);

    // --fluorescence none: the dye only absorbs, and no layers are written.
    const fs::path plain = dir.path() / "plain.exr";
    const auto n = runCli(dir, {"render", scene.string(), "-o", plain.string(), "--spp", "2", "--threads", "1", "--fluorescence", "none"});
    ASSERT_EQ(n.exitCode, 0) << n.err;
    EXPECT_FALSE(readExr(plain.string()).channels.count("fluorescent.R"));
    const auto bad = runCli(dir, {"render", scene.string(), "-o", plain.string(), "--fluorescence", "unbiased"});
    EXPECT_EQ(bad.exitCode, 2);
    EXPECT_TRUE(contains(bad.err, "--fluorescence")) << bad.err;
}

}  // namespace
}  // namespace fluorosim
