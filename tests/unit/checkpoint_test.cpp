// Interrupting and resuming a render: a pass cancelled half way leaves the film exactly at its last
// finished pass, a render continued from that state equals an uninterrupted one bit for bit, and
// checkpoint files round-trip the film and refuse damaged or mismatched files.
#include <gtest/gtest.h>

#include <atomic>
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
