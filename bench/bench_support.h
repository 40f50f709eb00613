#pragma once
// What the benchmarks share: the spectral database, scene loading with it (and with light sheets),
// rendering a scene's fluorescent layer, and the relative RMSE of an image against a reference.
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "database.h"
#include "optics/light_sheet.h"
#include "render/renderer.h"
#include "scene/scene_loader.h"

namespace fluorosim::bench {

inline const spectra::Database& db() {
    static const spectra::Database d(std::string(FLUOROSIM_SOURCE_DIR) + "/spectra/data");
    return d;
}

// A scene from JSON text (`file` names it and anchors relative paths) or from a file.
inline Scene loadBenchScene(const std::string& text, const std::filesystem::path& file) {
    return loadSceneFromString(
        text, file, [](const std::string& ref, const std::filesystem::path& base) { return db().resolve(ref, base); },
        [](const std::string& name, std::optional<double> ec, std::optional<double> qy) { return db().fluorophore(name, ec, qy); },
        [](const LightSheetSpec& spec) { return optics::makeLightSheet(spec); });
}
inline Scene loadBenchScene(const std::filesystem::path& file) {
    return loadScene(
        file, [](const std::string& ref, const std::filesystem::path& base) { return db().resolve(ref, base); },
        [](const std::string& name, std::optional<double> ec, std::optional<double> qy) { return db().fluorophore(name, ec, qy); },
        [](const LightSheetSpec& spec) { return optics::makeLightSheet(spec); });
}

struct FluorescentRender {
    std::vector<float> rgb;  // the film's "fluorescent" RGB layer
    RenderSummary summary;
};

// Renders `scene` in one pass of `spp` samples per pixel.
inline FluorescentRender renderFluorescentLayer(const Scene& scene, int spp, uint64_t seed, int threads = 0) {
    Film film(scene.camera.width, scene.camera.height, scene.spectral.lambdaMin, scene.spectral.lambdaMax, scene.spectral.binWidth,
              db().cie1931(), true);
    RenderOptions opt;
    opt.spp = spp;
    opt.seed = seed;
    opt.sppPerPass = 0;  // automatic
    opt.threads = threads;
    FluorescentRender r;
    r.summary = render(scene, film, opt);
    for (const RgbLayer& l : film.image(spp).rgbLayers)
        if (l.prefix == "fluorescent") r.rgb = l.rgb;
    return r;
}

// RMSE over the reference's mean.
template <class T>
double relativeRmse(const std::vector<T>& img, const std::vector<T>& ref) {
    double se = 0, mean = 0;
    for (size_t i = 0; i < img.size(); ++i) {
        se += std::pow(static_cast<double>(img[i]) - static_cast<double>(ref[i]), 2);
        mean += static_cast<double>(ref[i]);
    }
    return std::sqrt(se / static_cast<double>(img.size())) / (mean / static_cast<double>(img.size()));
}

}  // namespace fluorosim::bench
