// Interrupting and resuming a render: a pass cancelled half way leaves the film exactly at its last
// finished pass, a render continued from that state equals an uninterrupted one bit for bit, and
// checkpoint files round-trip the film and refuse damaged or mismatched files.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <fstream>
#include <sstream>

#include "core/errors.h"
#include "render/checkpoint.h"
#include "render/renderer.h"
#include "support/temp_dir.h"
#include "support/test_scenes.h"

namespace fluorosim {
namespace {

using testing::flatCmf;

// Paths of varied length, so rows finish in varied order.
Scene ballScene() { return testing::foggyBallScene(10, 12); }

Film makeFilm(const Scene& s) { return Film(s.camera.width, s.camera.height, 400, 700, 25, flatCmf(), true); }

// The film's accumulators as bytes: equal bytes mean a bit-identical image in every layer.
std::string state(const Film& f) {
    std::ostringstream os;
    f.writeState(os);
    return os.str();
}

RenderOptions options(int spp) {
    RenderOptions o;
    o.spp = spp;
    o.threads = 2;
    o.seed = 7;
    return o;
}

std::string uninterrupted(const Scene& scene, int spp) {
    Film f = makeFilm(scene);
    render(scene, f, options(spp));
    return state(f);
}

TEST(RenderInterruption, CancelInsideAPassKeepsTheLastFinishedPass) {
    const Scene scene = ballScene();
    Film film = makeFilm(scene);
    std::atomic<bool> cancel{false};
    RenderOptions o = options(6);
    o.cancel = &cancel;
    // Progress arrives after each row: cancel a third of the way through the third pass.
    const double third = (2.0 + 1.0 / 3.0) / 6.0;
    o.progress = [&](double f) {
        if (f > third) cancel = true;
    };
    const RenderSummary s = render(scene, film, o);
    EXPECT_TRUE(s.cancelled);
    EXPECT_EQ(s.sppCompleted, 2);
    EXPECT_EQ(state(film), uninterrupted(scene, 2));
}

TEST(RenderInterruption, ResumedRenderEqualsUninterruptedBitForBit) {
    const Scene scene = ballScene();
    Film film = makeFilm(scene);
    std::atomic<bool> cancel{false};
    RenderOptions o = options(7);
    o.cancel = &cancel;
    PathStats statsAtStop;
    o.passFinished = [&](const Film&, int done, const PathStats& stats) {
        if (done == 3) cancel = true, statsAtStop = stats;
    };
    const RenderSummary first = render(scene, film, o);
    ASSERT_EQ(first.sppCompleted, 3);
    EXPECT_EQ(first.stats.paths, statsAtStop.paths);

    RenderOptions rest = options(7);
    rest.firstSample = first.sppCompleted;
    const RenderSummary second = render(scene, film, rest);
    EXPECT_FALSE(second.cancelled);
    EXPECT_EQ(second.sppCompleted, 7);
    const auto pixels = static_cast<uint64_t>(scene.camera.width * scene.camera.height);
    EXPECT_EQ(first.stats.paths + second.stats.paths, 7 * pixels);
    EXPECT_EQ(state(film), uninterrupted(scene, 7));
}

// A time budget stops at the first pass that ends after it: the film is exactly a render of that spp.
TEST(RenderTimeBudget, StopsAfterAFinishedPassWithTheImageOfItsSpp) {
    const Scene scene = ballScene();
    Film film = makeFilm(scene);
    RenderOptions o = options(1000);
    o.timeBudgetSeconds = 1e-9;  // spent before the first pass ends
    const RenderSummary s = render(scene, film, o);
    EXPECT_TRUE(s.timeBudgetSpent);
    EXPECT_FALSE(s.cancelled);
    EXPECT_EQ(s.sppCompleted, 1);
    EXPECT_EQ(state(film), uninterrupted(scene, 1));

    // A budget that outlasts the target changes nothing.
    Film full = makeFilm(scene);
    RenderOptions generous = options(3);
    generous.timeBudgetSeconds = 1e6;
    const RenderSummary f = render(scene, full, generous);
    EXPECT_FALSE(f.timeBudgetSpent);
    EXPECT_EQ(f.sppCompleted, 3);
    EXPECT_EQ(state(full), uninterrupted(scene, 3));

    for (double bad : {-1.0, 2e9, std::nan("")}) {
        RenderOptions b = options(2);
        b.timeBudgetSeconds = bad;
        EXPECT_THROW(render(scene, full, b), ConfigError) << bad;
    }
}

// Automatic passes hold at least kMinPathsPerPass paths (a small image takes many samples per pixel
// a pass) and give the same image as passes of one sample.
TEST(RenderPasses, AutomaticPassesAreLongOnSmallImagesAndChangeNoBit) {
    RenderOptions o = options(100000);
    o.sppPerPass = 0;
    EXPECT_EQ(samplesPerPass(o, 32, 32), 64);
    EXPECT_EQ(samplesPerPass(o, 256, 256), 1);
    EXPECT_EQ(samplesPerPass(o, 300, 7), 32);  // ceil(65536 / 2100)
    o.spp = 10;
    EXPECT_EQ(samplesPerPass(o, 32, 32), 10);  // never more than the render's spp
    o.sppPerPass = 3;
    EXPECT_EQ(samplesPerPass(o, 32, 32), 3);

    const Scene scene = ballScene();
    Film film = makeFilm(scene);
    RenderOptions automatic = options(9);
    automatic.sppPerPass = 0;
    int passes = 0;
    automatic.passFinished = [&](const Film&, int, const PathStats&) { ++passes; };
    render(scene, film, automatic);
    EXPECT_EQ(passes, 1);
    EXPECT_EQ(state(film), uninterrupted(scene, 9));
}

TEST(RenderInterruption, ResumeBeyondTheTargetIsRefused) {
    const Scene scene = ballScene();
    Film film = makeFilm(scene);
    RenderOptions o = options(2);
    o.firstSample = 3;
    EXPECT_THROW(render(scene, film, o), ConfigError);
}

TEST(RenderCheckpoint, RoundTripsTheFilmAndItsRecord) {
    const Scene scene = ballScene();
    Film film = makeFilm(scene);
    const RenderSummary s = render(scene, film, options(3));
    const testing::TempDir dir;
    const std::string path = dir.file("out.exr.checkpoint").string();
    RenderCheckpoint c;
    c.sceneHash = 0x1234;
    c.seed = 7;
    c.fluorescence = "full";
    c.sppDone = 3;
    c.sppTarget = 10;
    c.seconds = 1.5;
    c.stats = s.stats;
    writeCheckpoint(path, c, film);
    EXPECT_FALSE(std::filesystem::exists(path + ".partial"));

    Film back = makeFilm(scene);
    const RenderCheckpoint r = readCheckpoint(path, back);
    EXPECT_EQ(state(back), state(film));
    EXPECT_EQ(r.sceneHash, c.sceneHash);
    EXPECT_EQ(r.seed, c.seed);
    EXPECT_EQ(r.fluorescence, c.fluorescence);
    EXPECT_EQ(r.sppDone, 3);
    EXPECT_EQ(r.sppTarget, 10);
    EXPECT_EQ(r.seconds, 1.5);
    EXPECT_EQ(r.stats.paths, s.stats.paths);
    EXPECT_EQ(r.stats.scatteringEvents, s.stats.scatteringEvents);
}

std::string readError(const std::string& path, Film& film) {
    try {
        (void)readCheckpoint(path, film);
    } catch (const Error& e) {
        return e.what();
    }
    return "(accepted)";
}

TEST(RenderCheckpoint, DamagedTruncatedForeignAndMismatchedFilesAreRefused) {
    const Scene scene = ballScene();
    Film film = makeFilm(scene);
    render(scene, film, options(1));
    const testing::TempDir dir;
    const std::string path = dir.file("c.checkpoint").string();
    RenderCheckpoint c;
    c.sppDone = c.sppTarget = 1;
    writeCheckpoint(path, c, film);
    std::string bytes;
    {
        std::ifstream in(path, std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    auto rewrite = [&](const std::string& b) { std::ofstream(path, std::ios::binary | std::ios::trunc) << b; };
    Film target = makeFilm(scene);

    std::string flipped = bytes;
    flipped[bytes.size() / 2] ^= 0x10;
    rewrite(flipped);
    EXPECT_NE(readError(path, target).find("damaged"), std::string::npos) << readError(path, target);
    rewrite(bytes.substr(0, bytes.size() - 100));
    EXPECT_NE(readError(path, target).find("damaged"), std::string::npos) << readError(path, target);
    rewrite("not a checkpoint at all");
    EXPECT_NE(readError(path, target).find("not a fluorosim render checkpoint"), std::string::npos);

    rewrite(bytes);
    Film other(scene.camera.width + 1, scene.camera.height, 400, 700, 25, flatCmf(), true);
    EXPECT_THROW((void)readCheckpoint(path, other), ConfigError);
    EXPECT_NE(readError(path, other).find("11x12"), std::string::npos) << readError(path, other);
    EXPECT_EQ(readError(path, target), "(accepted)");
}

}  // namespace
}  // namespace fluorosim
