#include "optics/scattered_emission.h"

#include <chrono>
#include <cmath>
#include <optional>
#include <unordered_map>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/parallel.h"
#include "core/rng.h"
#include "core/sampling.h"
#include "optics/dye_cells.h"
#include "optics/image_pooling.h"
#include "optics/index_key.h"
#include "render/photon_tracer.h"
#include "render/straight_line.h"
#include "render/weight_window.h"
#include "spectral/wavelength_sampler.h"
#include "volume/volume_fields.h"

namespace fluorosim::optics {
namespace {

// Independent slots of photons (photon i in slot i mod kSlots): the image does not depend on the thread
// count, and the slots' spread gives each pixel's variance.
constexpr int kSlots = 16;
// Share of the wavelength proposal spread uniformly, so that its density is positive wherever a dye emits.
constexpr double kUniformShare = 0.05;
// A weight window on the photons, by the importance of where they scatter: e^{τ(0) - τ(dz)} at a height dz
// above the focal plane (τ the scattering optical depth above it along the axis: the light a vertex sends the
// objective unscattered, against the focus's), times kFar / |dz| beyond kFar from the focal plane, at most 1
// (no photon is split for going where it matters more than at its source); and where no light a vertex sends
// the objective can reach the image, kInvisible / (1 + d / kFar) times that at d beyond the part that can (it
// may come back, the more seldom the farther). A photon whose power is over 2× or under ½× its unit power over
// the importance (its power at its source times the importance there) goes on as that many copies at it
// (Russian roulette below, splitting above): a photon that roams where it is unseen comes back as copies of
// bounded power, not as one whose power doubled at every unseen vertex. kFar is 100 µm: a vertex 200 µm above
// focus lights the whole image through its defocus disc, and rouletted from 20 µm on (the eighteenth
// session's) its survivors set a σs 2 /mm plane's level in AF488; without any fall, photons wander unseen
// through a large non-absorbing block (docs/performance.md, "The weight window far from focus").
constexpr double kInvisible = 0.5;
constexpr double kFarMm = 0.1;
constexpr uint64_t kPhotonsPerPoint = 4;
// The largest scattering optical depth across the slab around focus (ScatteredEmissionOptions::trackSlabMm,
// at the photon's wavelength) for which the flights' parts there are imaged along them; and the most σs times
// length one of their points carries (at most about that share of the photon's power).
constexpr double kTrackDepth = 0.25;
constexpr double kTrackPointDepth = 0.125;

// The photons' wavelengths: in proportion to the scene's dyes' emission times the detection, on 1 nm cells,
// each at its largest value over 9 points across it (a filter's edge inside a cell must not leave the density
// far below the detection there: a photon's weight is the detected emission over it), with kUniformShare
// spread uniformly so that the density is positive wherever a dye emits.
WavelengthSampler emissionWavelengths(const Scene& scene, const std::function<double(double)>& detection) {
    const double lo = scene.spectral.lambdaMin, hi = scene.spectral.lambdaMax;
    const int cells = std::max(1, static_cast<int>(std::ceil(hi - lo)));
    const double width = (hi - lo) / cells;
    std::vector<double> g(static_cast<size_t>(cells), 0.0);
    for (int c = 0; c < cells; ++c)
        for (int k = 0; k <= 8; ++k) {
            const double l = lo + (c + k / 8.0) * width;
            double e = 0;
            for (const Medium& m : scene.media)
                for (const DyeComponent& d : m.dyes()) e += d.dye.emissionPdf(l);
            g[static_cast<size_t>(c)] = std::max(g[static_cast<size_t>(c)], e * std::max(0.0, detection(l)));
        }
    double total = 0;
    for (double v : g) total += v;
    for (double& v : g) v = (total > 0 ? (1 - kUniformShare) * v / total : 0.0) + (total > 0 ? kUniformShare : 1.0) / cells;
    WavelengthSampler sampler(lo, hi, {}, true);
    sampler.setContinuousDensity(std::move(g));
    return sampler;
}

// The scattering optical depth along the axis through the image's centre, from a height dz above the focal
// plane up to the objective's front, at the detection-weighted mean wavelength (each medium at its scattering
// channel's largest value): the light a vertex there sends the objective unscattered, if the tissue is
// layered across the axis.
class AxisScattering {
public:
    AxisScattering(const Scene& scene, const Imaging& imaging, const std::function<double(double)>& detection) : front_(imaging.workingDistanceMm()) {
        double sum = 0, weighted = 0;
        for (double l = scene.spectral.lambdaMin + 0.5; l < scene.spectral.lambdaMax; l += 1) {
            const double d = std::max(0.0, detection(l));
            sum += d;
            weighted += d * l;
        }
        if (!(sum > 0)) return;
        const double lambda = weighted / sum;
        // From below the whole scene up to the front.
        const double below = 2 * (scene.geometry.extent() + length(imaging.centre())) + 1;
        const Vec3 bottom = imaging.centre() - imaging.axis() * below;
        const StraightLine line = traceStraightLine(scene, Ray{bottom, imaging.axis()}, mediumAt(scene, bottom, imaging.axis()), 0.0,
                                                    below + front_, LineSurfaces::ThroughAll);
        for (const RaySegment& seg : line.segments)
            if (seg.medium != kNone) {
                const Medium& m = scene.media[static_cast<size_t>(seg.medium)];
                const double sigma = m.isVacuumLike() ? 0.0 : m.scatteringAt(lambda) * m.channelMax()[kScatteringChannel];
                if (sigma > 0) layers_.push_back({seg.t0 - below, seg.t1 - below, sigma});
            }
        depthAtFocus_ = depthAbove(0);
    }
    double depthAbove(double dz) const {
        double tau = 0;
        for (const Layer& l : layers_) tau += l.sigma * std::max(0.0, std::min(l.s1, front_) - std::max(l.s0, dz));
        return tau;
    }
    // The light a vertex at dz sends the objective unscattered over a vertex's at the focus: e^{τ(0) - τ(dz)}.
    double overFocus(double dz) const { return std::exp(depthAtFocus_ - depthAbove(dz)); }
    double depthAtFocus() const { return depthAtFocus_; }

private:
    struct Layer {
        double s0, s1, sigma;  // along the axis from the focal plane (mm), and the scattering coefficient (/mm)
    };
    double front_;
    std::vector<Layer> layers_;
    double depthAtFocus_ = 0;  // τ(0), asked at every survival check
};


}  // namespace

void ScatteredEmissionOptions::validate() const {
    if (photons && (*photons == 1 || *photons > (uint64_t(1) << 40)))
        throw ConfigError("scattered emission photons must be 0 or lie in [2, 2^40], got " + std::to_string(*photons));
    if (!(photonsPerPixel >= 0) || photonsPerPixel > 1e6)
        throw ConfigError("scattered emission photons per pixel must lie in [0, 10^6], got " + std::to_string(photonsPerPixel));
    if (directions < 1 || directions > 1024) throw ConfigError("scattered emission directions per vertex must lie in [1, 1024], got " + std::to_string(directions));
    if (!(towardObjective >= 0 && towardObjective < 1))
        throw ConfigError("scattered emission share toward the objective must lie in [0, 1), got " + std::to_string(towardObjective));
    if (!(trackSlabMm >= 0 && trackSlabMm <= 1))
        throw ConfigError("scattered emission track slab must lie in [0, 1] mm, got " + std::to_string(trackSlabMm));
}

uint64_t ScatteredEmissionOptions::photonsFor(size_t pixels) const {
    if (photons) return *photons;
    const double n = std::round(photonsPerPixel * static_cast<double>(pixels));
    return n < 2 ? (n > 0 ? 2 : 0) : static_cast<uint64_t>(std::min(n, double(uint64_t(1) << 40)));
}

ScatteredEmissionImage traceScatteredEmission(const Scene& scene, const PathTracer& tracer, const Imaging& imaging, const CameraPathImaging& covered,
                                              const EmissionPoints& emission, const BeamExcitationField* field, const DyeCells* dyeCells,
                                              const std::function<double(double)>& detection, double exposureS,
                                              const ScatteredEmissionOptions& options, uint64_t seed, uint64_t streamKey, int threads,
                                              const std::atomic<bool>* cancel) {
    options.validate();
    const auto start = std::chrono::steady_clock::now();
    ScatteredEmissionImage out;
    const int width = imaging.width(), height = imaging.height();
    const size_t pixels = static_cast<size_t>(width) * height;
    out.electrons.assign(pixels, 0.0);
    out.variance.assign(pixels, 0.0);
    const uint64_t photons = options.photonsFor(pixels);
    if (photons == 0 || emission.empty()) return out;
    requireMemory(8.0 * kImageLevels * kSlots * static_cast<double>(pixels) * (field ? 2 : 1), "the scattered emission's images");
    const WavelengthSampler wavelengths = emissionWavelengths(scene, detection);
    const WidefieldPsf& psf = imaging.psf();
    const Vec3 axis = imaging.axis();
    const double cosMax = imaging.cosMax(), cone = imaging.coneSolidAngle();
    // The cone the photons leave into, the collection cone widened by 15°, and the share that do:
    // options.towardObjective × e^{-τ}, τ the scattering optical depth from the focus to the objective along the axis
    // at the detected light's mean wavelength. Where τ is large the detected light has scattered many times and
    // forgotten where it left for: in uncleared cortex (τ 5) the cone tripled the traced part's noise.
    const double cosLeave = std::cos(std::min(std::acos(cosMax) + kPi / 12, kPi / 2)), leaveSolidAngle = 2 * kPi * (1 - cosLeave);
    const AxisScattering axisScattering(scene, imaging, detection);
    const double towardObjective = options.towardObjective * std::exp(-axisScattering.depthAtFocus());
    const uint64_t key = mixBits(streamKey + 0x656d697373696f6eULL);
    const bool bends = hasRefractingSurfaces(scene);

    // Per slot and image level, the sum of the deposits on each pixel (levels allocated when first used).
    struct Slot {
        std::array<std::vector<double>, kImageLevels> level, fieldLevel;  // fieldLevel: the field's noise (fieldShare)
        uint64_t vertices = 0;
    };
    std::vector<Slot> slots(kSlots);

    // Images a vertex at v: light of power `power` (W, over the photon count) leaving with the phase lobe
    // around `dirIn` (or isotropically) at λ.
    struct Projector final : PhotonEvents {
        const Scene& scene;
        const PathTracer& tracer;
        const Imaging& imaging;
        const CameraPathImaging& covered;
        const WidefieldPsf& psf;
        const std::function<double(double)>& detection;
        Vec3 axis;
        double cosMax, cone, exposureS;
        int directions, width, height;
        Slot* slot = nullptr;
        Rng* rng = nullptr;
        // The share of the walking photon's power that is the field's half difference (its noise).
        double fieldShare = 0;
        Projector(const Scene& s, const PathTracer& t, const Imaging& i, const CameraPathImaging& c, const WidefieldPsf& p,
                  const std::function<double(double)>& d, Vec3 a, double cm, double co, double e, int dirs)
            : scene(s), tracer(t), imaging(i), covered(c), psf(p), detection(d), axis(a), cosMax(cm), cone(co), exposureS(e), directions(dirs),
              width(i.width()), height(i.height()) {}

        // Whether light leaving v toward the objective can land on the image: within the defocus disc's
        // radius and the PSF displacement's cut of the field.
        bool visible(const Imaging::Local& l) const { return !(beyondVisible(l) > 0); }
        // How far beyond that part v lies, across the axis (0 inside it).
        double beyondVisible(const Imaging::Local& l) const {
            const double reach = std::abs(l.dz) * imaging.tanThetaMax() + margin;
            const double ox = std::max(0.0, std::abs(l.x) - 0.5 * width * imaging.pixelMm());
            const double oy = std::max(0.0, std::abs(l.y) - 0.5 * height * imaging.pixelMm());
            return std::max(0.0, std::hypot(ox, oy) - reach);
        }
        double margin = 0;
        bool bends = true;  // whether the scene has refracting surfaces
        // Mitsuba 3's rule for lossless specular chains: after a few, each goes on with probability 0.95.
        int specularEvents = 0;
        double specularSurvival(const Photon&) override { return ++specularEvents > 8 ? 0.95 : 1.0; }
        // The walking photon's power at importance 1: at its source it lies inside its window.
        double unitPower = 0;
        const AxisScattering* axisScattering = nullptr;
        double importance(const Imaging::Local& l) const {
            const double dz = std::abs(l.dz);
            const double depth = std::min(1.0, (dz > kFarMm ? kFarMm / dz : 1.0) * axisScattering->overFocus(l.dz));
            const double beyond = beyondVisible(l);
            return beyond > 0 ? depth * kInvisible / (1 + beyond / kFarMm) : depth;
        }
        double survival(const Photon& ph, const Vec3& p) override { return weightWindowSurvival(ph.weight, importance(imaging.local(p)), unitPower); }

        void image(const Photon& ph, const Vec3& v, const HenyeyGreenstein* phase) { image(ph, v, phase, directions); }
        // The weight window's splitting, at the points a photon is imaged: it splits only after a collision, so a
        // photon that comes from where it matters less (a source far from focus or outside the field) reaches the
        // focal plane over the window's top, and its first points there would be imaged as one heavy photon. They
        // take as many times the directions instead (as many copies would).
        int copiesAt(const Photon& ph, const Vec3& x) const {
            const double q = weightWindowSurvival(ph.weight, importance(imaging.local(x)), unitPower);
            return q > 1 ? static_cast<int>(std::min(kMostCopiesAtAVertex, std::ceil(q))) : 1;
        }
        void image(const Photon& ph, const Vec3& v, const HenyeyGreenstein* phase, int n) {
            if (!(ph.weight > 0) || ph.medium == kNone) return;
            ++slot->vertices;
            const Imaging::Local lv = imaging.local(v);
            if (!visible(lv)) return;
            const double dz = lv.dz;
            const double toFront = imaging.workingDistanceMm() - dz;
            if (!(toFront > 0)) return;
            const int level = std::clamp(covered.imageLevel(v), 0, kImageLevels - 1);
            const double det = detection(ph.lambda);
            if (!(det > 0)) return;
            const SampledWavelengths wl = SampledWavelengths::atLine(ph.lambda, 1.0);
            std::vector<double>& img = slot->level[static_cast<size_t>(level)];
            if (img.empty()) img.assign(static_cast<size_t>(width) * height, 0.0);
            std::vector<double>& noise = slot->fieldLevel[static_cast<size_t>(level)];
            if (fieldShare != 0 && noise.empty()) noise.assign(static_cast<size_t>(width) * height, 0.0);
            // Directions of the cone from two techniques, the phase lobe (a draw outside the cone gives nothing)
            // and the cone uniformly, weighed by the balance heuristic (f/q, q = half of each density: f/q <= 2).
            // With an even count the techniques alternate and the cone's draws are stratified in azimuth, so that
            // a vertex's light spreads over its whole defocus disc (one direction put all of a pooled vertex into
            // one block of the ~50 its disc covers: most of the traced part's noise, docs/performance.md); with an
            // odd count each draw picks its technique at random. Either way each draw is one of the mixture.
            const bool alternate = phase && n % 2 == 0;
            const int coneDraws = !phase ? n : (alternate ? n / 2 : n);
            const double phi0 = rng->uniform();
            for (int k = 0; k < n; ++k) {
                const int stratum = !phase ? k : k / 2;
                auto coneDraw = [&] {
                    const double u = alternate || !phase ? (stratum + phi0) / coneDraws : rng->uniform();
                    return imaging.coneDirection(1 - rng->uniform() * (1 - cosMax), 2 * kPi * u);
                };
                Vec3 w;
                double f, q;
                if (!phase) {
                    w = coneDraw();
                    f = kInv4Pi;
                    q = 1 / cone;
                } else {
                    if (alternate ? k % 2 == 0 : rng->uniform() < 0.5) {
                        double pdf = 0;
                        w = phase->sample(ph.ray.d, rng->uniform(), rng->uniform(), &pdf);
                    } else {
                        w = coneDraw();
                    }
                    f = phase->pdf(ph.ray.d, w);
                    q = 0.5 * f + 0.5 / cone;
                }
                const double cosT = dot(w, axis);
                if (!(cosT >= cosMax) || !(f > 0)) continue;
                const Vec3 focal = v - w * (dz / cosT);
                const double T = transmittanceToCamera(v, focal, w, dz / cosT, toFront / cosT, ph.medium, wl);
                if (!(T > 0)) continue;
                // Where the camera paths' geometry lands the ray: its focal-plane crossing, less a draw of the
                // in-focus PSF's displacement, weighed there by h/h_geo.
                double radius = 0;
                const Vec3 x = focal - imaging.displacement(rng->uniform(), rng->uniform(), ph.lambda, &radius);
                const Imaging::Local lx = imaging.local(x);
                const double col = std::floor((lx.x - imaging.leftMm()) / imaging.pixelMm());
                const double row = std::floor((imaging.topMm() - lx.y) / imaging.pixelMm());
                if (!(col >= 0 && col < width && row >= 0 && row < height)) continue;
                const double R = psf.reweight(std::hypot(lx.x - lv.x, lx.y - lv.y), dz, ph.lambda);
                const double e = exposureS * det * ph.weight * (f / q) * T * R / n;
                if (!std::isfinite(e)) continue;
                img[static_cast<size_t>(row) * width + static_cast<size_t>(col)] += e;
                if (fieldShare != 0) noise[static_cast<size_t>(row) * width + static_cast<size_t>(col)] += e * fieldShare;
            }
        }
        // Transmittance from v along w (sv from the focal-plane crossing, `reach` to the objective's front) as
        // the camera paths weigh it (Imaging::cameraStart): straight to the front when nothing refracts between
        // the lower of v and the crossing and the front; else the paths start below the refraction nearest the
        // crossing and carry the rest as a weight, so v must lie below it, with no refraction between it and
        // the crossing (0 otherwise: light the camera's model leaves out).
        double transmittanceToCamera(const Vec3& v, const Vec3& focal, const Vec3& w, double sv, double reach, int medium,
                                     const SampledWavelengths& wl) {
            const Vec3 lower = sv < 0 ? v : focal;
            const double span = sv < 0 ? reach : reach - sv;
            // Without refracting surfaces no line can end at one: the tracer's transmittance finds the rest.
            const StraightLine line = bends ? traceStraightLine(scene, Ray{lower, w}, medium, 0.0, span, LineSurfaces::UntilRefraction) : StraightLine{};
            if (line.end != LineEnd::Refraction) return tracer.transmittance(v, v + w * reach, medium, wl, *rng)[0];
            const double toRefraction = line.segments.empty() ? 0.0 : line.segments.back().t1;
            const double sRefraction = (sv < 0 ? sv : 0.0) + toRefraction;  // from the crossing
            if (sv < 0 && sRefraction < 0) return 0.0;                        // a refraction between v and the focal plane
            if (!(sv < sRefraction)) return 0.0;                              // v above the refraction
            const int focalMedium = mediumAt(scene, focal, axis);
            const BentLine bent = imaging.collectionLine(scene, focal, focalMedium, w);
            if (!bent.open || !bent.bent()) return 0.0;
            const double rest = quadratureTransmittance(scene, bent, wl, 0.5, 1)[0];
            if (!(rest > 0)) return 0.0;
            const double toSurface = sRefraction - sv;
            return rest * tracer.transmittance(v, v + w * std::max(0.0, toSurface - 1e-7), medium, wl, *rng)[0];
        }
        // Within trackSlab of the focal plane, where the tissue is thin across the slab (σs × its thickness at
        // most kTrackDepth), the flights are imaged along their length, and their collisions there are not. The
        // choice depends on the medium, the point and the wavelength only, so each flight is one estimator or the
        // other, both unbiased. Where the tissue is thick (uncleared cortex) a flight's points weigh as much as
        // vertices and gain nothing: there they raised the traced part's variance over the brightest 1 % up to
        // 20× on one seed (docs/performance.md).
        double trackSlab = 0;
        bool collisionTracked = false;  // the current flight's slab is imaged along it
        void scattered(const Photon& ph, const Vec3& p) override {
            if (collisionTracked && std::abs(imaging.local(p).dz) < trackSlab) return;
            image(ph, p, &scene.media[static_cast<size_t>(ph.medium)].phase(), directions * copiesAt(ph, p));
        }
        // The flight's part within trackSlab of the focal plane, imaged at points stratified along it, each
        // weighed by σs there times its share of the length: at least two, each carrying σs × length at most
        // kTrackPointDepth, each in a quarter of a vertex's directions (two: one from the phase lobe, one from the
        // cone). A flight nearly parallel to the focal plane thus spreads its light along its track instead of
        // onto the one pixel under its collision.
        void flew(const Photon& ph, double tEnd, double reach, const Medium& m, double sigmaS) override {
            collisionTracked = false;
            if (!(trackSlab > 0) || !(sigmaS > 0) || !(ph.weight > 0) || m.isVacuumLike()) return;
            const double dz0 = imaging.local(ph.ray.o).dz, c = dot(ph.ray.d, axis);
            double a = 0, b = reach;
            if (c == 0) {
                if (!(std::abs(dz0) < trackSlab)) return;
            } else {
                const double t1 = (-trackSlab - dz0) / c, t2 = (trackSlab - dz0) / c;
                a = std::max(a, std::min(t1, t2));
                b = std::min(b, std::max(t1, t2));
            }
            if (!(b > a)) return;
            // The choice by the tissue where the ray enters the slab (not where it collides), so that it depends on
            // the ray alone where the scattering varies.
            ChannelValues ch{};
            m.channelValues(ph.ray.at(a), ch.data());
            if (!(sigmaS * ch[kScatteringChannel] * 2 * trackSlab <= kTrackDepth)) return;
            collisionTracked = true;
            b = std::min(b, tEnd);
            if (!(b > a) || !std::isfinite(b)) return;
            const double span = b - a;
            m.channelValues(ph.ray.at(a + 0.5 * span), ch.data());
            const int points = static_cast<int>(std::clamp(std::ceil(sigmaS * ch[kScatteringChannel] * span / kTrackPointDepth), 2.0, 4096.0));
            const int pointDirections = std::max(1, directions / 4);
            for (int j = 0; j < points; ++j) {
                const Vec3 x = ph.ray.at(a + (j + rng->uniform()) / points * span);
                m.channelValues(x, ch.data());
                Photon at = ph;
                at.weight *= sigmaS * ch[kScatteringChannel] * span / points;
                image(at, x, &m.phase(), pointDirections * copiesAt(ph, x));
            }
        }
        void reemitted(const Photon& ph, const Vec3& p) override { image(ph, p, nullptr, directions * copiesAt(ph, p)); }
    };

    // With a field, the photons leave the dye cells of media whose dye lies in grids (the computed emission
    // and the field-lit one); the lattice's points carry the computed emission of other media, if any.
    const DyeCells* fieldLit = field && !field->fields().empty() && dyeCells && !dyeCells->empty() ? dyeCells : nullptr;
    bool latticeNeeded = !fieldLit;
    for (size_t m = 0; m < scene.media.size() && !latticeNeeded; ++m)
        latticeNeeded = tracer.fluorescence().active(static_cast<int>(m)) && !(m < fieldLit->media().size() && fieldLit->media()[m]);
    const uint64_t fieldPhotons = fieldLit ? (latticeNeeded ? photons / 2 : photons) : 0;
    const uint64_t latticePhotons = photons - fieldPhotons;
    const uint64_t latticePoints = (latticePhotons + kPhotonsPerPoint - 1) / kPhotonsPerPoint;
    const uint64_t fieldPoints = (fieldPhotons + kPhotonsPerPoint - 1) / kPhotonsPerPoint;
    if (fieldLit) {
        out.fieldLitMedia = fieldLit->media();
        out.beamLitBox = field->fields().front().reach();
    }
    out.fieldLitMedia.resize(scene.media.size(), false);
    std::atomic<bool> stopped{false};
    parallelFor(kSlots, threads, [&](size_t s) {
        Slot& slot = slots[s];
        Projector projector(scene, tracer, imaging, covered, psf, detection, axis, cosMax, cone, exposureS, options.directions);
        projector.slot = &slot;
        projector.margin = psf.cutRadiusMm(scene.spectral.lambdaMax) + 2 * imaging.pixelMm();
        projector.axisScattering = &axisScattering;
        projector.bends = bends;
        projector.trackSlab = options.trackSlabMm;
        // Photons leave each source point kPhotonsPerPoint at a time: the point's excitation (a beam
        // transmittance traced back to where the beam entered) is the costliest part of a photon.
        const std::vector<double>& lines = tracer.lineWavelengths();
        // Per line, the excitation, and the field's half difference in it (its noise).
        std::vector<double> excitation(lines.size()), beyond(lines.size()), excitationNoise(lines.size()), beyondNoise(lines.size());
        for (uint64_t i = s, n = 0; i < latticePoints + fieldPoints; i += kSlots, ++n) {
            if (cancel && (n & 63) == 0 && cancel->load()) {
                stopped = true;
                return;
            }
            Rng rng = Rng::forKey(seed, key, i);
            projector.rng = &rng;
            const bool fromLattice = i < latticePoints;
            Vec3 p;
            int medium = kNone;
            double pdf = 0;
            if (fromLattice) {
                const EmissionPoints::Sample y = emission.sample(rng.uniform(), rng.uniform(), rng.uniform(), rng.uniform());
                if (!(y.pdf > 0) || !covered.computesUnscatteredAt(y.p)) continue;
                p = y.p;
                pdf = y.pdf;
                medium = mediumAt(scene, p, axis);
                if (out.tracesFieldLit(medium)) continue;  // the dye cells carry that medium's emission
            } else {
                const DyeCells::Sample y = fieldLit->sample(rng.uniform(), rng.uniform(), rng.uniform(), rng.uniform());
                if (!(y.pdf > 0) || mediumAt(scene, y.p, axis) != y.medium) continue;
                p = y.p;
                pdf = y.pdf;
                medium = y.medium;
            }
            if (medium == kNone || !tracer.fluorescence().active(medium)) continue;
            ChannelValues ch;
            scene.media[static_cast<size_t>(medium)].channelValues(p, ch.data());
            bool lit = false;
            // The computed emission (the beams' light inside their cores where the computed part covers p) and,
            // from the dye cells, the field's light beyond it: its straight light is the photons' too.
            const bool computed = covered.computesUnscatteredAt(p);
            for (size_t l = 0; l < lines.size(); ++l) {
                excitation[l] = computed ? tracer.coreMeanRadiance(p, medium, lines[l], field, rng) : 0.0;
                const auto phi = field && (computed || !fromLattice) ? field->scatteredByCore(p, lines[l]) : std::nullopt;
                const BeamExcitationField::CoreAndOutside parts = phi.value_or(BeamExcitationField::CoreAndOutside{});
                excitationNoise[l] = computed ? parts.core.halfDifference : 0.0;
                beyond[l] = fromLattice ? 0.0 : (computed ? 0.0 : parts.core.mean) + parts.outside.mean;
                beyondNoise[l] = fromLattice ? 0.0 : (computed ? 0.0 : parts.core.halfDifference) + parts.outside.halfDifference;
                // Beyond the computed part, inside the field's box, the beams' core emission is the photons' too.
                if (!fromLattice && !computed && out.tracesBeamLit(p, medium)) beyond[l] += tracer.coreMeanRadiance(p, medium, lines[l], nullptr, rng);
                lit = excitation[l] + beyond[l] > 0 || lit;
            }
            if (!lit) continue;
            const uint64_t first = fromLattice ? i * kPhotonsPerPoint : (i - latticePoints) * kPhotonsPerPoint;
            const uint64_t ofKind = fromLattice ? latticePhotons : fieldPhotons;
            const uint64_t count = std::min<uint64_t>(kPhotonsPerPoint, ofKind - first);
            for (uint64_t k = 0; k < count; ++k) {
                const SampledWavelengths drawn = wavelengths.sample(0.0, rng.uniform());
                const double lambda = drawn.lambda[0], pdfLambda = drawn.pdf[0];
                double source = 0, straight = 0;  // the emission coefficient at λ (radiance per mm), and what the photons image straight
                double sourceNoise = 0, straightNoise = 0;  // the field's half differences in them
                for (size_t l = 0; l < lines.size(); ++l)
                    if (excitation[l] + beyond[l] > 0) {
                        const double kernel = tracer.fluorescence().kernel(medium, ch.data(), lines[l], lambda);
                        source += kernel * (excitation[l] + beyond[l]);
                        straight += kernel * beyond[l];
                        sourceNoise += kernel * (excitationNoise[l] + beyondNoise[l]);
                        straightNoise += kernel * beyondNoise[l];
                    }
                if (!(source > 0) || !(pdfLambda > 0)) continue;
                // Power per unit of the scene's radiance scale: 4π × the emission coefficient × the volume, with
                // lengths across the ray in m (as the camera paths' étendue has them) and along it in mm.
                Photon ph;
                ph.medium = medium;
                ph.lambda = lambda;
                ph.weight = 4 * kPi * source * 1e-6 / (pdf * pdfLambda * static_cast<double>(ofKind));
                projector.specularEvents = 0;
                // The field-lit emission's straight light is the photons' too (the computed image holds the rest).
                if (straight > 0) {
                    Photon direct = ph;
                    direct.weight *= straight / source;
                    projector.fieldShare = straightNoise / straight;
                    projector.image(direct, p, nullptr);
                }
                // Its direction from the mixture of the cone toward the objective and the sphere, weighed by the
                // isotropic density over the mixture's.
                const bool towardCone = rng.uniform() < towardObjective;
                const double u1 = rng.uniform(), u2 = rng.uniform();
                const Vec3 dir = towardCone ? imaging.coneDirection(1 - u1 * (1 - cosLeave), 2 * kPi * u2) : sampleUniformSphere(u1, u2);
                const double pdfDir = (1 - towardObjective) * kInv4Pi + (dot(dir, axis) >= cosLeave - 1e-12 ? towardObjective / leaveSolidAngle : 0.0);
                ph.ray = Ray{p, dir};
                ph.weight *= kInv4Pi / pdfDir;
                projector.unitPower = ph.weight * projector.importance(imaging.local(p));
                projector.fieldShare = sourceNoise / source;
                walkPhoton(scene, ph, rng, projector, false);
            }
        }
    });
    out.complete = !stopped;
    // Each slot's image, its pooled levels spread back to pixels; the estimate is their sum, and kSlots times
    // each is an independent estimate of it.
    std::vector<std::vector<double>> slotImages(kSlots, std::vector<double>(pixels, 0.0));
    parallelFor(kSlots, threads, [&](size_t s) {
        std::vector<double>& img = slotImages[s];
        for (int k = 0; k < kImageLevels; ++k) {
            const std::vector<double>& level = slots[s].level[static_cast<size_t>(k)];
            if (level.empty()) continue;
            if (k == 0) {
                for (size_t i = 0; i < pixels; ++i) img[i] += level[i];
            } else {
                const std::vector<double> pooled = poolImage(level, width, height, k);
                for (size_t i = 0; i < pixels; ++i) img[i] += pooled[i];
            }
        }
    });
    for (int s = 0; s < kSlots; ++s) {
        for (size_t i = 0; i < pixels; ++i) out.electrons[i] += slotImages[static_cast<size_t>(s)][i];
        out.vertices += slots[static_cast<size_t>(s)].vertices;
    }
    // The field's noise: per level the slots' sum (the spreading is linear), spread back to pixels.
    if (field) {
        out.fieldHalfDifference.assign(pixels, 0.0);
        for (int k = 0; k < kImageLevels; ++k) {
            std::vector<double> sum;
            for (const Slot& slot : slots) {
                const std::vector<double>& level = slot.fieldLevel[static_cast<size_t>(k)];
                if (level.empty()) continue;
                if (sum.empty()) sum.assign(pixels, 0.0);
                for (size_t i = 0; i < pixels; ++i) sum[i] += level[i];
            }
            if (sum.empty()) continue;
            if (k > 0) sum = poolImage(sum, width, height, k);
            for (size_t i = 0; i < pixels; ++i) out.fieldHalfDifference[i] += sum[i];
        }
    }
    for (int s = 0; s < kSlots; ++s)
        for (size_t i = 0; i < pixels; ++i) out.variance[i] += sqr(kSlots * slotImages[static_cast<size_t>(s)][i] - out.electrons[i]);
    for (double& v : out.variance) v /= double(kSlots) * (kSlots - 1);
    for (std::vector<double>& img : slotImages)
        for (double& v : img) v *= kSlots;
    out.slots = std::move(slotImages);
    out.photons = photons;
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return out;
}

ScatteredEmissionImage pooledTraces(const ScatteredEmissionImage& a, const ScatteredEmissionImage& b) {
    if (b.photons == 0) return a;
    if (a.photons == 0) return b;
    if (a.slots.size() != b.slots.size() || a.electrons.size() != b.electrons.size())
        throw std::logic_error("pooledTraces: traces of different planes");
    const double wa = double(a.photons) / double(a.photons + b.photons), wb = 1 - wa;
    ScatteredEmissionImage out;
    const size_t pixels = a.electrons.size(), slots = a.slots.size();
    out.electrons.assign(pixels, 0.0);
    out.variance.assign(pixels, 0.0);
    out.slots.assign(slots, std::vector<double>(pixels, 0.0));
    for (size_t s = 0; s < slots; ++s)
        for (size_t i = 0; i < pixels; ++i) {
            out.slots[s][i] = wa * a.slots[s][i] + wb * b.slots[s][i];
            out.electrons[i] += out.slots[s][i] / double(slots);
        }
    for (size_t s = 0; s < slots; ++s)
        for (size_t i = 0; i < pixels; ++i) out.variance[i] += sqr(out.slots[s][i] - out.electrons[i]) / (double(slots) * double(slots - 1));
    if (a.fieldHalfDifference.size() == pixels && b.fieldHalfDifference.size() == pixels) {
        out.fieldHalfDifference.assign(pixels, 0.0);
        for (size_t i = 0; i < pixels; ++i) out.fieldHalfDifference[i] = wa * a.fieldHalfDifference[i] + wb * b.fieldHalfDifference[i];
    }
    out.photons = a.photons + b.photons;
    out.vertices = a.vertices + b.vertices;
    out.fieldLitMedia = a.fieldLitMedia;
    out.beamLitBox = a.beamLitBox;
    out.seconds = a.seconds + b.seconds;
    out.complete = a.complete && b.complete;
    return out;
}

}  // namespace fluorosim::optics
