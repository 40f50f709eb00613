#pragma once
// The options of an acquisition as a user gives them, checked and applied in one place: shared by
// `fluorosim acquire` and the Python module, so both refuse the same values with the same messages
// (named by the CLI's options).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/units.h"
#include "optics/acquisition.h"
#include "optics/microscope.h"

namespace fluorosim::optics {

struct AcquireRequest {
    std::optional<int> planes, spp, maxSpp;
    std::optional<double> noiseRatio;
    std::string estimator = "split";
    std::optional<std::string> step;
    std::optional<int64_t> seed;
    int threads = 0;
    std::vector<std::string> channels;  // names to acquire (default: all)
    std::optional<std::string> exposure;  // a time ("20 ms"), or "auto" / "auto:F" (autoExpose at F of the full well, 0.5 by default)
    std::optional<int64_t> fieldPhotons;   // the excitation field's photons per beam line side and plane (0: off)
    std::optional<double> fieldMarginUm, fieldReachUm;  // how far it reaches beyond the computed region and from the focal plane
    std::optional<double> fieldDiffuseUm;               // its diffuse light's node spacing
    std::optional<int64_t> emissionPhotons;  // the scattered emission's photons per plane and channel (0: paths carry it)
    std::optional<double> emissionTrackUm;   // how near focus its scattering is imaged along the flights (0: at the vertices)
};

// --exposure: a time replaces the scene's; "auto[:F]" asks for autoExpose after the stack is acquired.
struct ExposureRequest {
    std::optional<double> seconds;
    std::optional<double> autoFraction;
};

inline ExposureRequest parseExposure(const std::optional<std::string>& text) {
    ExposureRequest r;
    if (!text) return r;
    if (text->rfind("auto", 0) == 0) {
        const std::string rest = text->substr(4);
        if (rest.empty()) r.autoFraction = 0.5;
        else {
            double f = 0;
            size_t used = 0;
            try {
                if (rest[0] == ':') f = std::stod(rest.substr(1), &used);
            } catch (const std::exception&) {
                used = 0;
            }
            if (rest[0] != ':' || used == 0 || used != rest.size() - 1 || !(f > 0 && f <= 1))
                throw ConfigError("--exposure: expected a time (\"20 ms\"), \"auto\" or \"auto:F\" with F the full-well fraction in (0, 1], got \"" +
                                  *text + "\"");
            r.autoFraction = f;
        }
        return r;
    }
    r.seconds = parseQuantity(*text, Dimension::Time, "--exposure");
    if (!(*r.seconds > 0) || !std::isfinite(*r.seconds)) throw ConfigError("--exposure: must be positive, got \"" + *text + "\"");
    return r;
}

// What can be checked before the scene is read (so that a typo is refused before loading and its warnings).
inline void checkAcquireRequest(const AcquireRequest& a) {
    if (a.threads < 0 || a.threads > 4096) throw ConfigError("--threads: must lie in [0, 4096], got " + std::to_string(a.threads));
    if (a.seed && *a.seed < 0) throw ConfigError("--seed: must be >= 0, got " + std::to_string(*a.seed));
    if (a.planes && (*a.planes < 1 || *a.planes > 4096)) throw ConfigError("--planes: must lie in [1, 4096], got " + std::to_string(*a.planes));
    if (a.step && !(parseQuantity(*a.step, Dimension::Length, "--step") > 0)) throw ConfigError("--step: must be positive, got " + *a.step);
    if (a.spp && (*a.spp < 1 || *a.spp > (1 << 24))) throw ConfigError("--spp: must lie in [1, 16777216], got " + std::to_string(*a.spp));
    if (!estimatorFromName(a.estimator)) throw ConfigError("--estimator: expected \"split\" or \"path\", got \"" + a.estimator + "\"");
    if (a.noiseRatio && (!(*a.noiseRatio > 0) || !std::isfinite(*a.noiseRatio)))
        throw ConfigError("--noise-ratio: must be positive and finite, got " + std::to_string(*a.noiseRatio));
    parseExposure(a.exposure);
    if (a.fieldPhotons && (*a.fieldPhotons < 0 || *a.fieldPhotons == 1 || *a.fieldPhotons > (int64_t(1) << 40)))
        throw ConfigError("--field-photons: must be 0 (no field) or lie in [2, 2^40], got " + std::to_string(*a.fieldPhotons));
    // At most 10 mm: the field's grids grow with the box.
    for (const auto& [value, option] : {std::pair{a.fieldMarginUm, "--field-margin-um"}, std::pair{a.fieldReachUm, "--field-reach-um"}})
        if (value && (!(*value >= 0) || !(*value <= 1e4))) throw ConfigError(std::string(option) + ": must lie in [0, 10000], got " + std::to_string(*value));
    // At least 1 um: finer nodes would not fit a reach's box in memory, and the diffuse light is smooth.
    if (a.fieldDiffuseUm && !(*a.fieldDiffuseUm == 0 || (*a.fieldDiffuseUm >= 1 && *a.fieldDiffuseUm <= 1e3)))
        throw ConfigError("--field-diffuse-um: must be 0 (no diffuse grid) or lie in [1, 1000], got " + std::to_string(*a.fieldDiffuseUm));
    if (a.emissionPhotons && (*a.emissionPhotons < 0 || *a.emissionPhotons == 1 || *a.emissionPhotons > (int64_t(1) << 40)))
        throw ConfigError("--emission-photons: must be 0 (paths carry the scattered emission) or lie in [2, 2^40], got " + std::to_string(*a.emissionPhotons));
    if (a.emissionTrackUm && !(*a.emissionTrackUm >= 0 && *a.emissionTrackUm <= 1000))
        throw ConfigError("--emission-track-um: must lie in [0, 1000], got " + std::to_string(*a.emissionTrackUm));
}

// The stack overrides (planes, step) of acquire and fit, applied to `m` and validated against the scene.
inline void applyStackOverrides(Microscope& m, const Scene& scene, std::optional<int> planes, const std::optional<std::string>& step) {
    if (planes) {
        if (*planes < 1 || *planes > 4096) throw ConfigError("--planes: must lie in [1, 4096], got " + std::to_string(*planes));
        m.stack.planes = *planes;
    }
    if (step) m.stack.stepMm = parseQuantity(*step, Dimension::Length, "--step");
    if (!(m.stack.stepMm > 0)) throw ConfigError("--step: must be positive, got " + step.value_or(""));
    m.validate(scene);
}

// Applies the stack overrides (planes, step) to `m`, validates it against the scene, and returns the
// acquisition options. Throws ConfigError naming the option and its value.
inline AcquireOptions applyAcquireRequest(const AcquireRequest& a, const Scene& scene, Microscope& m) {
    checkAcquireRequest(a);
    applyStackOverrides(m, scene, a.planes, a.step);
    if (const ExposureRequest e = parseExposure(a.exposure); e.seconds) m.detector.exposureS = *e.seconds;

    AcquireOptions o;
    o.spp = a.spp.value_or(scene.render.spp);
    if (o.spp < 1 || o.spp > (1 << 24)) throw ConfigError("--spp: must lie in [1, 16777216], got " + std::to_string(o.spp));
    o.seed = a.seed ? static_cast<uint64_t>(*a.seed) : scene.render.seed;
    const auto estimator = estimatorFromName(a.estimator);
    if (!estimator) throw ConfigError("--estimator: expected \"split\" or \"path\", got \"" + a.estimator + "\"");
    o.estimator = *estimator;
    if (a.noiseRatio) {
        if (!(*a.noiseRatio > 0) || !std::isfinite(*a.noiseRatio))
            throw ConfigError("--noise-ratio: must be positive and finite, got " + std::to_string(*a.noiseRatio));
        o.noiseRatio = *a.noiseRatio;
    }
    if (a.maxSpp) {
        if (!a.noiseRatio) throw ConfigError("--max-spp: only with --noise-ratio (adaptive sampling)");
        if (*a.maxSpp < o.spp || *a.maxSpp > (1 << 24))
            throw ConfigError("--max-spp: must lie in [spp = " + std::to_string(o.spp) + ", 16777216], got " + std::to_string(*a.maxSpp));
        o.maxSpp = *a.maxSpp;
    }
    if (o.noiseRatio) o.maxSpp = std::max(o.maxSpp, o.spp);
    o.threads = a.threads;
    if (a.fieldPhotons) o.field.photons = static_cast<uint64_t>(*a.fieldPhotons);
    if (a.fieldMarginUm) o.field.marginUm = *a.fieldMarginUm;
    if (a.fieldReachUm) o.field.reachUm = *a.fieldReachUm;
    if (a.fieldDiffuseUm) o.field.diffuseUm = *a.fieldDiffuseUm;
    if (a.emissionPhotons) o.emission.photons = static_cast<uint64_t>(*a.emissionPhotons);
    if (a.emissionTrackUm) o.emission.trackSlabMm = *a.emissionTrackUm * 1e-3;
    return o;
}

}  // namespace fluorosim::optics
