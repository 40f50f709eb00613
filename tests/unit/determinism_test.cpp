// The image must not depend on the number of threads (random streams are keyed per pixel and sample).
#include <gtest/gtest.h>

#include "core/errors.h"
#include "render/renderer.h"
#include "support/test_scenes.h"

namespace fluorosim {
namespace {

using testing::flatCmf;

Scene smallScene() { return testing::foggyBallScene(12, 9); }

ExrImage renderWith(const Scene& scene, int threads, int sppPerPass) {
    Film film(scene.camera.width, scene.camera.height, 400, 700, 20, flatCmf());
    RenderOptions opt;
    opt.spp = 8;
    opt.threads = threads;
    opt.seed = 42;
    opt.sppPerPass = sppPerPass;
    render(scene, film, opt);
    return film.image(opt.spp);
}

TEST(Determinism, SameImageForAnyThreadCountAndPassSize) {
    const Scene scene = smallScene();
    const ExrImage a = renderWith(scene, 1, 8);
    const ExrImage b = renderWith(scene, 2, 1);
    const ExrImage c = renderWith(scene, 2, 3);
    ASSERT_EQ(a.rgb.size(), b.rgb.size());
    EXPECT_EQ(a.rgb, b.rgb);
    EXPECT_EQ(a.rgb, c.rgb);
    EXPECT_EQ(a.spectral[0].values, b.spectral[0].values);
    double sum = 0;
    for (float v : a.rgb) sum += v;
    EXPECT_GT(sum, 0.0);
}

// A distributed render: bands of rows rendered into their own films, sent as bytes and placed into the
// whole film give the whole render's image exactly, layers included.
TEST(Determinism, BandsRenderedApartGiveTheSameImage) {
    const Scene scene = smallScene();
    const int w = scene.camera.width, h = scene.camera.height;
    RenderOptions opt;
    opt.spp = 6;
    opt.seed = 42;
    Film whole(w, h, 400, 700, 20, flatCmf(), true);
    render(scene, whole, opt);
    Film gathered(w, h, 400, 700, 20, flatCmf(), true);
    for (const auto& [first, rows] : {std::pair{0, 4}, std::pair{4, 1}, std::pair{5, 4}}) {
        Film band = gathered.band(rows);
        RenderOptions o = opt;
        o.firstRow = first;
        o.threads = 1;
        render(scene, band, o);
        Film received(w, rows, 400, 700, 20, flatCmf(), true);
        received.setSums(band.sums());
        gathered.placeRows(first, received);
    }
    const ExrImage a = whole.image(opt.spp), b = gathered.image(opt.spp);
    EXPECT_EQ(a.rgb, b.rgb);
    ASSERT_EQ(a.rgbLayers.size(), b.rgbLayers.size());
    ASSERT_FALSE(a.rgbLayers.empty());
    for (size_t l = 0; l < a.rgbLayers.size(); ++l) EXPECT_EQ(a.rgbLayers[l].rgb, b.rgbLayers[l].rgb);
    for (size_t i = 0; i < a.spectral.size(); ++i) EXPECT_EQ(a.spectral[i].values, b.spectral[i].values);

    Film band(w, 4, 400, 700, 20, flatCmf(), true);
    EXPECT_THROW(gathered.placeRows(6, band), Error);  // rows 6..9 of a 9-row film
    EXPECT_THROW(band.setSums(whole.sums()), Error);
    RenderOptions beyond = opt;
    beyond.firstRow = 6;
    EXPECT_THROW(render(scene, band, beyond), Error);
}

TEST(Determinism, DifferentSeedsDiffer) {
    const Scene scene = smallScene();
    Film f1(scene.camera.width, scene.camera.height, 400, 700, 20, flatCmf());
    Film f2(scene.camera.width, scene.camera.height, 400, 700, 20, flatCmf());
    RenderOptions opt;
    opt.spp = 2;
    opt.seed = 1;
    render(scene, f1, opt);
    opt.seed = 2;
    render(scene, f2, opt);
    EXPECT_NE(f1.image(2).rgb, f2.image(2).rgb);
}

TEST(Cancellation, KeepsFinishedPasses) {
    const Scene scene = smallScene();
    Film film(scene.camera.width, scene.camera.height, 400, 700, 20, flatCmf());
    std::atomic<bool> cancel{false};
    RenderOptions opt;
    opt.spp = 8;
    opt.sppPerPass = 2;
    opt.cancel = &cancel;
    opt.passFinished = [&](const Film&, int done, const PathStats&) {
        if (done == 4) cancel = true;
    };
    const RenderSummary s = render(scene, film, opt);
    EXPECT_TRUE(s.cancelled);
    EXPECT_EQ(s.sppCompleted, 4);
    // The first 4 samples of every pixel are exactly those of an uninterrupted 4 spp render.
    Film ref(scene.camera.width, scene.camera.height, 400, 700, 20, flatCmf());
    opt.spp = 4;
    opt.cancel = nullptr;
    opt.passFinished = nullptr;
    render(scene, ref, opt);
    EXPECT_EQ(film.image(4).rgb, ref.image(4).rgb);
}

}  // namespace
}  // namespace fluorosim
