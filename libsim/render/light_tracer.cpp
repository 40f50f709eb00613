#include "render/light_tracer.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "core/errors.h"
#include "core/math.h"
#include "core/rng.h"
#include "core/sampling.h"
#include "render/photon_merging.h"
#include "render/photon_tracer.h"
#include "render/specular_chain.h"
#include "scene/light_sampler.h"

namespace fluorosim {
namespace {

// A connection is made with probability min(1, kConnectAt e^(-σt d)), d the vertex's depth below the
// liquid's surface (the chain's first segment is at least that long, so its transmittance is at most
// e^(-σt d)), and divided by that probability: deep vertices, whose chains carry almost nothing, are
// mostly skipped, and a made connection weighs at most 1/kConnectAt of an unattenuated one.
constexpr double kConnectAt = 8;

double spectralPower(const Spectrum& s, const Scene& scene) { return s.integral(scene.spectral.lambdaMin, scene.spectral.lambdaMax); }

// Connects the vertices of photons in a stack's liquid to the camera through the stack, and those of
// re-emitted photons on opaque surfaces straight to it.
class CameraConnections final : public PhotonEvents {
public:
    CameraConnections(const Scene& scene, const PathTracer& tracer, double pixelArea, double photonsPerSample, Rng& rng,
                      std::vector<FilmSplat>& out, LightTraceStats& stats, const CameraSegments* merging)
        : scene_(scene), tracer_(tracer), pixelArea_(pixelArea), perSample_(photonsPerSample), rng_(rng), out_(out), stats_(stats),
          merging_(merging) {}

    void scattered(const Photon& ph, const Vec3& p) override {
        const HenyeyGreenstein& phase = scene_.media[static_cast<size_t>(ph.medium)].phase();
        const auto f = [&](const Vec3& w) { return phase.pdf(ph.ray.d, w); };
        connect(ph, p, f);
        if (merging_) merging_->gather(ph, p, f, perSample_, out_, stats_.merges);
    }
    void reemitted(const Photon& ph, const Vec3& p) override {
        const auto f = [](const Vec3&) { return 1 / (4 * kPi); };
        connect(ph, p, f);
        if (merging_) merging_->gather(ph, p, f, perSample_, out_, stats_.merges);
    }
    // Re-emitted light on an opaque, non-specular surface, seen straight from the camera.
    void surfaceScattered(const Photon& ph, const SurfaceHit& hit, const Vec3& n, const Material& mat, double eta) override {
        if (!ph.fluorescent || mat.isSpecular() || mat.isTransmissive()) return;
        if (merging_) merging_->gatherOnSurface(ph, hit, n, perSample_, out_, stats_.merges);
        const Camera& cam = scene_.camera;
        const Vec3 toCamera = cam.position - hit.p;
        const double d2 = dot(toCamera, toCamera);
        const Vec3 wCamera = toCamera / std::sqrt(d2);
        const auto pixel = pixelSeeing(-wCamera);
        if (!pixel) return;
        ++stats_.connections;
        const SampledWavelengths wl = SampledWavelengths::atLine(ph.lambda, 1.0);
        const Frame frame = Frame::fromNormal(n);
        const double f = mat.f(frame.toLocal(wCamera), frame.toLocal(-ph.ray.d), wl, eta, TransportMode::Radiance)[0] * std::abs(dot(n, wCamera));
        if (!(f > 0)) return;
        const double T = tracer_.transmittance(hit.p, cam.position, ph.medium, wl, rng_, &hit.n, hit.epsilon)[0];
        if (!(T > 0)) return;
        out_.push_back(FilmSplat{pixel->x, pixel->y, ph.lambda, ph.weight * f * T * pixel->importance / (d2 * perSample_), true});
    }

private:
    struct Pixel {
        int32_t x, y;
        double importance;  // the pinhole's for one pixel: 1 / (A_pixel cos³θ)
    };
    // The pixel whose camera ray leaves along unit w (cameraRay inverted), if any.
    std::optional<Pixel> pixelSeeing(const Vec3& w) const {
        const Camera& cam = scene_.camera;
        const double z = dot(w, cam.frame.n);
        if (!(z > 0)) return std::nullopt;
        const double aspect = static_cast<double>(cam.width) / cam.height;
        const double px = (dot(w, cam.frame.s) / z / (cam.tanHalfFovY * aspect) + 1) * 0.5 * cam.width;
        const double py = (1 - dot(w, cam.frame.t) / z / cam.tanHalfFovY) * 0.5 * cam.height;
        if (!(px >= 0 && px < cam.width && py >= 0 && py < cam.height)) return std::nullopt;
        return Pixel{static_cast<int32_t>(px), static_cast<int32_t>(py), 1 / (pixelArea_ * z * z * z)};
    }

    template <class Phase>
    void connect(const Photon& ph, const Vec3& p, Phase&& phaseValue) {
        const int stack = tracer_.shellsAround(p, ph.medium);
        if (stack < 0) return;
        const SphericalShells* sh = &tracer_.shells()[static_cast<size_t>(stack)];
        const SampledWavelengths wl = SampledWavelengths::atLine(ph.lambda, 1.0);
        double keep = 1;
        const Medium& m = scene_.media[static_cast<size_t>(ph.medium)];
        if (m.isHomogeneous()) {
            ChannelValues ch{};
            m.channelValues(p, ch.data());
            const MediumSample c = m.spectra(wl).at(ch.data());
            keep = std::min(1.0, kConnectAt * std::exp(-(c.sigmaA[0] + c.sigmaS[0]) * (sh->radius[0] - length(p - sh->center))));
            if (rng_.uniform() >= keep) return;
        }
        const Vec3 camera = scene_.camera.position;
        std::array<ShellPath, 4> roots;
        const int count = shellPaths(*sh, p, camera, roots);
        for (int k = 0; k < count; ++k) {
            const ShellPath& r = roots[static_cast<size_t>(k)];
            ++stats_.connections;
            const double f = phaseValue(r.direction);
            if (!(f > 0)) continue;
            const auto pixel = pixelSeeing(-r.exitDirection);
            if (!pixel) continue;
            const double dAdw = areaPerSolidAngle(*sh, p, r, camera, r.exitDirection);
            if (!(dAdw > 0)) continue;
            const double T = tracer_.chainTransmittance(*sh, p, r, camera, wl, rng_)[0];
            if (!(T > 0)) continue;
            // The generalized geometry term is 1 / (dA⊥ at the camera per dω at p): the indices of refraction
            // cancel against the radiance's n² (docs/model.md).
            const double value = ph.weight * f * T * r.fresnel * pixel->importance / (dAdw * keep * perSample_);
            out_.push_back(FilmSplat{pixel->x, pixel->y, ph.lambda, value, ph.fluorescent});
        }
    }

    const Scene& scene_;
    const PathTracer& tracer_;
    double pixelArea_, perSample_;
    Rng& rng_;
    std::vector<FilmSplat>& out_;
    LightTraceStats& stats_;
    const CameraSegments* merging_;
};

}  // namespace

LightTracer::LightTracer(const Scene& scene, const PathTracer& tracer) : scene_(scene), tracer_(tracer), lights_(scene) {
    if (scene.render.fluorescence == FluorescenceModel::Paper)
        throw ConfigError("the light integrator traces the full fluorescence model; the paper's model needs \"path\" or \"mnee\"");
    const Camera& cam = scene.camera;
    if (cam.medium != kNone) throw ConfigError("the light integrator needs the camera outside every medium");
    for (const SphericalShells& s : tracer.shells())
        if (length(cam.position - s.center) <= s.radius[static_cast<size_t>(s.count - 1)])
            throw ConfigError("the light integrator needs the camera outside every glass sphere");
    const double aspect = static_cast<double>(cam.width) / cam.height;
    pixelArea_ = (2 * cam.tanHalfFovY * aspect / cam.width) * (2 * cam.tanHalfFovY / cam.height);
    std::vector<double> power;
    for (const Light& l : scene.lights) {
        double p = 0;
        if (const auto* a = std::get_if<AreaLight>(&l)) {
            p = spectralPower(a->emission.radiance, scene) * scene.geometry.area(a->shape) * kPi * (a->emission.twoSided ? 2 : 1);
        } else if (const auto* pl = std::get_if<PointLight>(&l)) {
            p = spectralPower(pl->intensity, scene) * 4 * kPi * kMm2PerM2;
        } else if (const auto* sl = std::get_if<SpotLight>(&l)) {
            p = spectralPower(sl->intensity, scene) * 2 * kPi * (1 - sl->cosTotalWidth) * kMm2PerM2;
        } else {
            throw ConfigError("the light integrator does not trace beams (light sheets); use \"path\" or \"mnee\"");
        }
        power.push_back(std::max(0.0, p));
    }
    double total = 0;
    for (double p : power) total += p;
    if (!(total > 0)) throw ConfigError("the light integrator needs a light that emits inside the spectral range");
    double cdf = 0;
    for (size_t i = 0; i < power.size(); ++i) {
        cdf += power[i] / total;
        emitters_.push_back({&scene.lights[i], i + 1 == power.size() ? 1.0 : cdf});
    }
}

void LightTracer::trace(uint64_t seed, uint64_t index, std::vector<FilmSplat>& out, LightTraceStats& stats,
                        const CameraSegments* merging) const {
    ++stats.photons;
    Rng rng = Rng::forKey(seed, index, 0x6c696768);
    const double u = rng.uniform();
    const auto it = std::find_if(emitters_.begin(), emitters_.end(), [&](const Emitter& e) { return u < e.cdf; });
    const Emitter& e = it == emitters_.end() ? emitters_.back() : *it;
    const double pSelect = e.cdf - (&e == &emitters_.front() ? 0.0 : (&e - 1)->cdf);
    if (!(pSelect > 0)) return;
    Photon ph;
    const double lo = scene_.spectral.lambdaMin, hi = scene_.spectral.lambdaMax;
    if (const auto* a = std::get_if<AreaLight>(e.light)) {
        // A point by area on the emitting shape, a cosine-distributed direction on its emitting side.
        const uint32_t shape = a->shape;
        const double u1 = rng.uniform(), u2 = rng.uniform();
        auto [p, n] = lights_.pointByArea(*a, u1, u2);
        double sides = 1;
        if (a->emission.twoSided) {
            sides = 2;
            if (rng.uniform() < 0.5) n = -n;
        }
        const Vec3 local = sampleCosineHemisphere(rng.uniform(), rng.uniform());
        const Vec3 dir = Frame::fromNormal(n).toWorld(local);
        ph.weight = sampleLightWavelength(a->emission.radiance, lo, hi, rng, &ph.lambda) * scene_.geometry.area(shape) * kPi * sides / pSelect;
        ph.ray = Ray{p, dir};
        const ShapeInfo& info = scene_.shapes[shape];
        ph.medium = info.isInterface ? (dot(dir, n) > 0 ? info.outsideMedium : info.insideMedium) : kNone;
        ph.tMin = (scene_.geometry.isSphere(shape) ? sphereRayEpsilon(p) : rayEpsilon(p)) / std::max(local.z, 1e-2);
    } else if (const auto* pl = std::get_if<PointLight>(e.light)) {
        ph.weight = sampleLightWavelength(pl->intensity, lo, hi, rng, &ph.lambda) * 4 * kPi * kMm2PerM2 / pSelect;
        ph.ray = Ray{pl->position, sampleUniformSphere(rng.uniform(), rng.uniform())};
    } else if (const auto* sl = std::get_if<SpotLight>(e.light)) {
        const double cosT = 1 - rng.uniform() * (1 - sl->cosTotalWidth), phi = 2 * kPi * rng.uniform();
        const double sinT = std::sqrt(std::max(0.0, 1 - cosT * cosT));
        const Vec3 dir = Frame::fromNormal(sl->direction).toWorld(Vec3(sinT * std::cos(phi), sinT * std::sin(phi), cosT));
        ph.weight = sampleLightWavelength(sl->intensity, lo, hi, rng, &ph.lambda) * LightSampler::spotFalloff(*sl, dir) * 2 * kPi *
                    (1 - sl->cosTotalWidth) * kMm2PerM2 / pSelect;
        ph.ray = Ray{sl->position, dir};
    }
    if (!(ph.weight > 0)) return;
    CameraConnections connections(scene_, tracer_, pixelArea_, photonsPerSample(), rng, out, stats, merging);
    walkPhoton(scene_, ph, rng, connections, true);
}

}  // namespace fluorosim
