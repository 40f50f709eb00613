// `fluorosim view` through the CLI: batch screenshots and movies, and bad input (no display, missing
// or foreign stacks, bad options), each a one-line error with a non-zero exit code.
#include <gtest/gtest.h>

#include <cstdlib>
#include <optional>

#include "viewer_fixture.h"

namespace fluorosim::testing {
namespace {

// Sets an environment variable for the scope of a test (the CLI inherits it), then restores it.
class ScopedEnv {
public:
    ScopedEnv(const char* name, const char* value) : name_(name) {
        if (const char* old = std::getenv(name)) old_ = old;
        if (value) setenv(name, value, 1);
        else unsetenv(name);
    }
    ~ScopedEnv() {
        if (old_) setenv(name_, old_->c_str(), 1);
        else unsetenv(name_);
    }

private:
    const char* name_;
    std::optional<std::string> old_;
};

std::vector<std::string> viewArgs(const ViewerScene& s, std::vector<std::string> extra) {
    std::vector<std::string> args{"view", s.path().string(), "--no-swc", "--screenshot", (s.dir() / "shot.png").string()};
    args.insert(args.end(), extra.begin(), extra.end());
    return args;
}

TEST(ViewerCli, ScreenshotHasTheRequestedSize) {
    TempDir dir;
    ViewerScene s(dir);
    const RunResult r = runCli(dir, viewArgs(s, {"--size", "320x200", "--view", "xz"}));
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(pngSize(s.dir() / "shot.png"), (std::array<int, 2>{320, 200}));
}

TEST(ViewerCli, MovieFramesAndOgg) {
    TempDir dir;
    ViewerScene s(dir);
    const RunResult frames = runCli(dir, {"view", s.path().string(), "--no-swc", "--movie", (dir.path() / "frames").string(), "--size", "200x160"});
    ASSERT_EQ(frames.exitCode, 0) << frames.err;
    EXPECT_EQ(pngSize(dir.path() / "frames" / "frame_0004.png"), (std::array<int, 2>{200, 160}));
    const RunResult ogv = runCli(dir, {"view", s.path().string(), "--no-swc", "--movie", (dir.path() / "o.ogv").string(), "--movie-kind", "orbit",
                                       "--frames", "4", "--size", "200x160", "--view", "3d"});
    ASSERT_EQ(ogv.exitCode, 0) << ogv.err;
    EXPECT_EQ(readFile(dir.path() / "o.ogv").substr(0, 4), "OggS");
}

TEST(ViewerCli, NoDisplayIsAClearError) {
    TempDir dir;
    ViewerScene s(dir);
    {
        ScopedEnv noDisplay("DISPLAY", nullptr);
        const RunResult r = runCli(dir, viewArgs(s, {}));
        EXPECT_EQ(r.exitCode, 4);
        expectOneLineError(r, {"no X display", "DISPLAY is not set", "xvfb-run"});
    }
    {
        ScopedEnv wrongDisplay("DISPLAY", ":4711");
        const RunResult r = runCli(dir, viewArgs(s, {}));
        EXPECT_EQ(r.exitCode, 4);
        expectOneLineError(r, {"cannot open X display", ":4711"});
    }
    EXPECT_FALSE(fs::exists(s.dir() / "shot.png"));
}

TEST(ViewerCli, MissingStackIsAnIoError) {
    TempDir dir;
    ViewerScene s(dir);
    const RunResult r = runCli(dir, viewArgs(s, {"--stack", (dir.path() / "nowhere.ome.tif").string()}));
    EXPECT_EQ(r.exitCode, 3);
    expectOneLineError(r, {"nowhere.ome.tif", "no such file"});
}

TEST(ViewerCli, StackOfTheWrongSizeIsRefused) {
    TempDir dir;
    ViewerScene s(dir);
    const fs::path small = s.writeStack("small.ome.tif", 32, 32, kPlanes, kPixelUm, {"AF488"}, [](int, int, int, int) { return 1.0; });
    const RunResult r = runCli(dir, viewArgs(s, {"--stack", small.string()}));
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"small.ome.tif", "32 x 32", "64 x 64"});
}

TEST(ViewerCli, StackWithOtherPixelsOrChannelsIsRefused) {
    TempDir dir;
    ViewerScene s(dir);
    const fs::path coarse = s.writeStack("coarse.ome.tif", 64, 64, kPlanes, 1.0, {"AF488"}, [](int, int, int, int) { return 1.0; });
    const RunResult r1 = runCli(dir, viewArgs(s, {"--stack", coarse.string()}));
    EXPECT_EQ(r1.exitCode, 2);
    expectOneLineError(r1, {"coarse.ome.tif", "1.000000 um", "0.406250 um"});
    const fs::path gfp = s.writeStack("gfp.ome.tif", 64, 64, kPlanes, kPixelUm, {"GFP"}, [](int, int, int, int) { return 1.0; });
    const RunResult r2 = runCli(dir, viewArgs(s, {"--stack", gfp.string()}));
    EXPECT_EQ(r2.exitCode, 2);
    expectOneLineError(r2, {"no channel named \"GFP\"", "AF488"});
    const fs::path notOme = dir.write("plain.ome.tif", "not a tiff");
    const RunResult r3 = runCli(dir, viewArgs(s, {"--stack", notOme.string()}));
    EXPECT_EQ(r3.exitCode, 3);
    expectOneLineError(r3, {"plain.ome.tif"});
}

TEST(ViewerCli, StackNeedsAMicroscope) {
    TempDir dir;
    ViewerScene s(dir);
    const fs::path stack = s.writeStack("a.ome.tif", 64, 64, kPlanes, kPixelUm, {"AF488"}, [](int, int, int, int) { return 1.0; });
    s.scene().erase("microscope");
    s.write();
    const RunResult r = runCli(dir, viewArgs(s, {"--stack", stack.string()}));
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"--stack", "no microscope block"});
}

TEST(ViewerCli, BadOptionsNameTheOptionAndValue) {
    TempDir dir;
    ViewerScene s(dir);
    const std::vector<std::pair<std::vector<std::string>, std::vector<std::string>>> cases = {
        {{"--size", "640"}, {"--size", "\"640\""}},
        {{"--size", "20x20"}, {"--size", "20x20"}},
        {{"--view", "sideways"}, {"--view", "\"sideways\"", "overview", "compare"}},
        {{"--view", "compare"}, {"--view compare", "--stack"}},
        {{"--channels", "AF999"}, {"--channels", "\"AF999\"", "AF488, AF594"}},
        {{"--plane", "7"}, {"--plane", "5 planes", "got 7"}},
        {{"--blend", "sum"}, {"--blend", "\"sum\""}},
        {{"--volume-mapper", "fast"}, {"--volume-mapper", "\"fast\""}},
        {{"--colors", "green,plaid"}, {"--colors", "\"plaid\""}},
        {{"--iso", "AF594=lots"}, {"--iso", "AF594=lots"}},
        {{"--iso", "AF647"}, {"--iso", "\"AF647\""}},
        {{"--band", "2"}, {"--band", "--exr"}},
    };
    for (const auto& [extra, parts] : cases) {
        const RunResult r = runCli(dir, viewArgs(s, extra));
        EXPECT_EQ(r.exitCode, 2) << extra[0] << " " << extra[1] << ": " << r.err;
        expectOneLineError(r, parts);
    }
}

TEST(ViewerCli, MissingFilesAreIoErrors) {
    TempDir dir;
    ViewerScene s(dir);
    const RunResult scene = runCli(dir, {"view", (dir.path() / "none.json").string(), "--screenshot", (dir.path() / "x.png").string()});
    EXPECT_EQ(scene.exitCode, 3);
    expectOneLineError(scene, {"none.json"});
    const RunResult exr = runCli(dir, {"view", "--exr", (dir.path() / "none.exr").string(), "--screenshot", (dir.path() / "x.png").string()});
    EXPECT_EQ(exr.exitCode, 3);
    expectOneLineError(exr, {"none.exr"});
    const RunResult folder = runCli(dir, {"view", s.path().string(), "--screenshot", (dir.path() / "no" / "x.png").string()});
    EXPECT_EQ(folder.exitCode, 3);
    expectOneLineError(folder, {"does not exist"});
}

TEST(ViewerCli, NothingToShowIsAnError) {
    TempDir dir;
    const RunResult r = runCli(dir, {"view", "--screenshot", (dir.path() / "x.png").string()});
    EXPECT_EQ(r.exitCode, 2);
    expectOneLineError(r, {"give a scene file, or --exr"});
}

TEST(ViewerCli, FitIsAcceptedAndReportedAsNotAvailable) {
    TempDir dir;
    ViewerScene s(dir);
    const RunResult r = runCli(dir, viewArgs(s, {"--fit", dir.path().string()}));
    EXPECT_EQ(r.exitCode, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "--fit")) << r.err;
    EXPECT_TRUE(contains(r.err, "not available yet")) << r.err;
}

}  // namespace
}  // namespace fluorosim::testing
