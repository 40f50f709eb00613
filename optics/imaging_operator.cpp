#include "optics/imaging_operator.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>

#include "core/errors.h"
#include "core/parallel.h"

namespace fluorosim::optics {
namespace {

double secondsSince(std::chrono::steady_clock::time_point t) { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count(); }

}  // namespace

// ------------------------------------------------------------------------------------------------
// Parameters.

ParameterMap ParameterMap::labels(const std::vector<LabelKey>& keys, bool includeUnlabelled) {
    ParameterMap m;
    for (const LabelKey& k : keys) {
        if (k.value == 0 && !includeUnlabelled) continue;
        if (std::find(m.keys_.begin(), m.keys_.end(), k) != m.keys_.end()) continue;
        m.keys_.push_back(k);
    }
    std::sort(m.keys_.begin(), m.keys_.end());
    for (const LabelKey& k : m.keys_) {
        FitParameter p;
        p.label = k;
        p.name = k.value ? "label " + std::to_string(k.value) : "unlabelled";
        m.parameters_.push_back(p);
    }
    return m;
}

ParameterMap ParameterMap::grid(double cellMm, const std::vector<const EmissionLattice*>& lattices) {
    if (!(cellMm > 0) || !std::isfinite(cellMm)) throw ConfigError("grid parameters: the cell must be positive, got " + std::to_string(cellMm * 1e3) + " um");
    ParameterMap m;
    m.grid_ = true;
    m.cellMm_ = cellMm;
    std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    for (const EmissionLattice* l : lattices)
        for (size_t p = 0; p < l->size(); ++p) {
            const LatticePoint& q = l->point(p);
            const std::array<double, 3> x{q.x, q.y, q.z};
            for (int a = 0; a < 3; ++a) {
                lo[static_cast<size_t>(a)] = std::min(lo[static_cast<size_t>(a)], x[static_cast<size_t>(a)]);
                hi[static_cast<size_t>(a)] = std::max(hi[static_cast<size_t>(a)], x[static_cast<size_t>(a)]);
            }
        }
    if (lo[0] > hi[0]) return m;
    double nodes = 1;
    for (int a = 0; a < 3; ++a) {
        m.origin_[static_cast<size_t>(a)] = std::floor(lo[static_cast<size_t>(a)] / cellMm) * cellMm;
        m.counts_[static_cast<size_t>(a)] = static_cast<int>(std::floor((hi[static_cast<size_t>(a)] - m.origin_[static_cast<size_t>(a)]) / cellMm)) + 2;
        nodes *= m.counts_[static_cast<size_t>(a)];
    }
    if (nodes > 5e7) throw ConfigError("grid parameters: a cell of " + std::to_string(cellMm * 1e3) + " um makes " + std::to_string(nodes) + " grid nodes; use a larger cell");
    m.nodeParameter_.assign(static_cast<size_t>(nodes), -1);
    std::vector<uint8_t> used(static_cast<size_t>(nodes), 0);
    std::vector<std::pair<int, double>> b;
    for (const EmissionLattice* l : lattices)
        for (size_t p = 0; p < l->size(); ++p) {
            bool dyed = false;
            for (int s = 0; s < l->slots(); ++s) dyed = dyed || l->concentration(p, s) > 0;
            if (!dyed) continue;
            const LatticePoint& q = l->point(p);
            m.basis(q.x, q.y, q.z, b);
            for (const auto& [node, w] : b)
                if (w > 0) used[static_cast<size_t>(node)] = 1;
        }
    const LatticeGeometry& g = lattices.front()->geometry();
    for (size_t n = 0; n < used.size(); ++n) {
        if (!used[n]) continue;
        const int i = static_cast<int>(n % static_cast<size_t>(m.counts_[0]));
        const int j = static_cast<int>((n / static_cast<size_t>(m.counts_[0])) % static_cast<size_t>(m.counts_[1]));
        const int k = static_cast<int>(n / (static_cast<size_t>(m.counts_[0]) * static_cast<size_t>(m.counts_[1])));
        m.nodeParameter_[n] = static_cast<int>(m.parameters_.size());
        FitParameter p;
        p.node = true;
        p.cell = {i, j, k};
        p.name = "node (" + std::to_string(i) + ", " + std::to_string(j) + ", " + std::to_string(k) + ")";
        p.centreMm = g.world(m.origin_[0] + i * cellMm, m.origin_[1] + j * cellMm, m.origin_[2] + k * cellMm);
        m.parameters_.push_back(p);
    }
    return m;
}

int ParameterMap::parameterOf(const LabelKey& key) const {
    if (grid_) return -1;
    const auto it = std::lower_bound(keys_.begin(), keys_.end(), key);
    return it != keys_.end() && *it == key ? static_cast<int>(it - keys_.begin()) : -1;
}

void ParameterMap::basis(double x, double y, double z, std::vector<std::pair<int, double>>& out) const {
    out.clear();
    const std::array<double, 3> u{(x - origin_[0]) / cellMm_, (y - origin_[1]) / cellMm_, (z - origin_[2]) / cellMm_};
    std::array<int, 3> c{};
    std::array<double, 3> f{};
    for (int a = 0; a < 3; ++a) {
        const double v = u[static_cast<size_t>(a)];
        c[static_cast<size_t>(a)] = std::clamp(static_cast<int>(std::floor(v)), 0, counts_[static_cast<size_t>(a)] - 2);
        f[static_cast<size_t>(a)] = std::clamp(v - c[static_cast<size_t>(a)], 0.0, 1.0);
    }
    for (int n = 0; n < 8; ++n) {
        const int i = c[0] + (n & 1), j = c[1] + ((n >> 1) & 1), k = c[2] + ((n >> 2) & 1);
        const double w = ((n & 1) ? f[0] : 1 - f[0]) * (((n >> 1) & 1) ? f[1] : 1 - f[1]) * (((n >> 2) & 1) ? f[2] : 1 - f[2]);
        out.push_back({static_cast<int>((static_cast<size_t>(k) * counts_[1] + static_cast<size_t>(j)) * counts_[0] + static_cast<size_t>(i)), w});
    }
}

double ParameterMap::gridFactor(double x, double y, double z, const std::vector<double>& theta) const {
    thread_local std::vector<std::pair<int, double>> b;
    basis(x, y, z, b);
    double f = 0, w = 0;
    for (const auto& [node, weight] : b) {
        const int param = nodeParameter_[static_cast<size_t>(node)];
        if (param < 0 || !(weight > 0)) continue;
        f += weight * theta[static_cast<size_t>(param)];
        w += weight;
    }
    // Where no node around is a parameter there is no dye to scale; where some are, the others hold none.
    return w > 0 ? f + (1 - w) * (f / w) : 1.0;
}

std::array<double, 3> ParameterMap::nodePosition(size_t parameter) const {
    const std::array<int, 3>& c = parameters_.at(parameter).cell;
    return {origin_[0] + c[0] * cellMm_, origin_[1] + c[1] * cellMm_, origin_[2] + c[2] * cellMm_};
}

void ParameterMap::entries(const EmissionLattice& lattice, size_t p, std::vector<Entry>& out) const {
    out.clear();
    if (!grid_) {
        if (!lattice.hasParts()) throw ConfigError("label parameters need a lattice split by label");
        for (const EmissionLattice::Part* part = lattice.partsBegin(p); part != lattice.partsEnd(p); ++part)
            out.push_back({parameterOf(lattice.labels()[part->key]), part->slot, part->value});
        return;
    }
    const LatticePoint& q = lattice.point(p);
    thread_local std::vector<std::pair<int, double>> b;
    basis(q.x, q.y, q.z, b);
    for (int slot = 0; slot < lattice.slots(); ++slot) {
        const double c = lattice.concentration(p, slot);
        if (!(c > 0)) continue;
        for (const auto& [node, w] : b)
            if (w > 0) out.push_back({nodeParameter_[static_cast<size_t>(node)], static_cast<uint16_t>(slot), c * w});
    }
}

// ------------------------------------------------------------------------------------------------
// The operator.

struct StackOperator::Channel {
    size_t microscopeChannel = 0;
    std::string name;
    ChannelImaging imaging;
    std::vector<std::vector<Light>> planeLights;
    const EmissionLattice* lattice = nullptr;
    std::unique_ptr<EmissionGains> gains;
    // Per plane, the beams' scattered excitation (null where there is none), traced as the acquisition
    // traces it (same stream): its emission is part of each column, as it is of the computed image.
    std::vector<std::unique_ptr<const BeamExcitationField>> fields;
    const BeamExcitationField* fieldAt(int plane) const { return fields.empty() ? nullptr : fields[static_cast<size_t>(plane)].get(); }
};

StackOperator::StackOperator(const Scene& scene, const Microscope& m, std::vector<size_t> channels, const AcquireOptions& options)
    : scene_(scene), width_(m.width), height_(m.height), planes_(m.stack.planes), options_(options), objective_(m.objective),
      detector_(m.detector) {
    options_.estimator = Estimator::Split;
    for (int k = 0; k < planes_; ++k) {
        offsets_.push_back(m.planeOffsetMm(k));
        focalPlanes_.push_back(m.focalPlaneAt(offsets_.back()));
    }
    for (size_t c : channels) {
        auto ch = std::make_unique<Channel>();
        ch->microscopeChannel = c;
        ch->name = m.channels[c].name;
        ch->imaging = setUpChannelImaging(scene, m, c, options_, true);
        for (int k = 0; k < planes_; ++k) ch->planeLights.push_back(m.lightsAt(scene, m.channels[c], offsets_[static_cast<size_t>(k)]));
        if (ch->imaging.unscattered && ch->imaging.unscattered->active()) {
            ch->lattice = ch->imaging.unscattered->lattice(scene, options_.threads, options.cancel);
            if (!ch->lattice) throw Cancelled("cancelled while building the emission lattice");
        }
        channels_.push_back(std::move(ch));
    }
    bool any = false;
    for (const auto& ch : channels_) any = any || ch->lattice;
    if (!any) throw ConfigError("no channel computes an image: no beam line of the chosen channels excites a dye they detect");
}

StackOperator::~StackOperator() = default;

const UnscatteredModel& StackOperator::model(size_t slot) const { return *channels_.at(slot)->imaging.unscattered; }

std::vector<LabelKey> StackOperator::labels() const {
    std::vector<LabelKey> all;
    for (const auto& ch : channels_)
        if (ch->lattice) all.insert(all.end(), ch->lattice->labels().begin(), ch->lattice->labels().end());
    std::sort(all.begin(), all.end());
    all.erase(std::unique(all.begin(), all.end()), all.end());
    return all;
}

std::vector<const EmissionLattice*> StackOperator::lattices() const {
    std::vector<const EmissionLattice*> out;
    for (const auto& ch : channels_)
        if (ch->lattice) out.push_back(ch->lattice);
    return out;
}

bool StackOperator::refreshGains(const Scene& scene, const std::atomic<bool>* cancel) {
    const auto start = std::chrono::steady_clock::now();
    for (auto& ch : channels_) {
        if (!ch->lattice) continue;
        auto g = ch->imaging.unscattered->gainsFor(scene, options_.threads, cancel);
        if (!g) return false;
        ch->gains = std::move(g);
        ch->fields.clear();
        for (int k = 0; k < planes_; ++k) {
            const PathTracer tracer(scene, ch->planeLights[static_cast<size_t>(k)]);
            const FocalPlane& focus = focalPlanes_[static_cast<size_t>(k)];
            const Imaging imaging(objective_, focus, detector_, width_, height_, ch->imaging.psfAt(focus));
            AcquireOptions o = options_;
            o.cancel = cancel;
            ch->fields.push_back(traceExcitationField(scene, tracer, imaging, *ch->imaging.unscattered, o, planeStreamKey(ch->name, k)));
            if (cancel && cancel->load()) return false;
        }
    }
    gainSeconds_ += secondsSince(start);
    return true;
}

namespace {

// A plane's lit points as emissions, one per (point, slot), and each one's parameter entries.
struct PlaneTerms {
    std::vector<PointEmission> emissions;  // e = the gain (photoelectrons per mol/L)
    std::vector<uint32_t> entryStart;      // per emission, into entries (one past the last at the end)
    std::vector<ParameterMap::Entry> entries;
};

PlaneTerms planeTerms(const UnscatteredModel& model, const EmissionLattice& lattice, const EmissionGains& gains, const std::vector<Light>& lights,
                      double offset, const ParameterMap& map, int threads, const BeamExcitationField* field) {
    const LatticeGeometry& g = model.geometry();
    const auto [first, last] = lattice.zRange(offset - g.halfDepthMm(), offset + g.halfDepthMm());
    std::vector<double> gain;
    gains.planeGains(lights, offset, first, last, gain, threads, field);
    PlaneTerms t;
    const int slots = lattice.slots();
    std::vector<ParameterMap::Entry> entries;
    for (size_t p = first; p < last; ++p) {
        bool lit = false;
        for (int s = 0; s < slots; ++s) lit = lit || gain[(p - first) * static_cast<size_t>(slots) + static_cast<size_t>(s)] > 0;
        if (!lit) continue;
        map.entries(lattice, p, entries);
        const LatticePoint& q = lattice.point(p);
        for (int s = 0; s < slots; ++s) {
            const double gs = gain[(p - first) * static_cast<size_t>(slots) + static_cast<size_t>(s)];
            if (!(gs > 0)) continue;
            const size_t before = t.entries.size();
            for (const ParameterMap::Entry& e : entries)
                if (e.slot == s && e.coefficient != 0) t.entries.push_back(e);
            if (t.entries.size() == before) continue;
            t.entryStart.push_back(static_cast<uint32_t>(before));
            PointEmission em = pointEmission(g, q, offset);
            em.e = gs;
            em.dye = static_cast<uint32_t>(model.dyes().firstOfMedium[static_cast<size_t>(q.medium)] + s);
            t.emissions.push_back(em);
        }
    }
    t.entryStart.push_back(static_cast<uint32_t>(t.entries.size()));
    return t;
}

}  // namespace

SparseColumns StackOperator::columns(const ParameterMap& map, const std::atomic<bool>* cancel, bool withTail) const {
    SparseColumns out;
    out.pixels.resize(map.size());
    out.values.resize(map.size());
    const size_t planePixels = static_cast<size_t>(width_) * height_;
    // Parameters in batches, so that a batch's dense images fit in memory.
    const size_t batch = std::max<size_t>(1, std::min<size_t>(map.size(), (size_t(1) << 27) / (planePixels * sizeof(double)) + 1));
    for (size_t slot = 0; slot < channels_.size(); ++slot) {
        const Channel& ch = *channels_[slot];
        if (!ch.lattice) continue;
        if (!ch.gains) throw ConfigError("stack operator: refresh the gains before asking for columns");
        for (int k = 0; k < planes_; ++k) {
            if (cancel && cancel->load()) throw Cancelled("cancelled while computing the fit's columns");
            const auto start = std::chrono::steady_clock::now();
            const PlaneTerms terms = planeTerms(*ch.imaging.unscattered, *ch.lattice, *ch.gains, ch.planeLights[static_cast<size_t>(k)],
                                                offsets_[static_cast<size_t>(k)], map, options_.threads, ch.fieldAt(k));
            const size_t base = planeImage(slot, k) * planePixels;
            for (size_t b0 = 0; b0 < map.size(); b0 += batch) {
                const size_t b1 = std::min(map.size(), b0 + batch);
                std::vector<PointEmission> ems;
                for (size_t i = 0; i < terms.emissions.size(); ++i)
                    for (uint32_t e = terms.entryStart[i]; e < terms.entryStart[i + 1]; ++e) {
                        const ParameterMap::Entry& en = terms.entries[e];
                        if (en.parameter < static_cast<int>(b0) || en.parameter >= static_cast<int>(b1)) continue;
                        PointEmission em = terms.emissions[i];
                        em.e *= en.coefficient;
                        em.target = static_cast<uint32_t>(static_cast<size_t>(en.parameter) - b0);
                        ems.push_back(em);
                    }
                if (ems.empty()) continue;
                const std::vector<std::vector<double>> images = ch.imaging.unscattered->projector(offsets_[static_cast<size_t>(k)])
                                                                    .project(ems, static_cast<int>(b1 - b0), options_.threads, cancel,
                                                                             withTail ? ProjectorParts::All : ProjectorParts::WithoutTail);
                if (images.empty()) throw Cancelled("cancelled while computing the fit's columns");
                for (size_t j = b0; j < b1; ++j) {
                    const std::vector<double>& img = images[j - b0];
                    double peak = 0;
                    for (double v : img) peak = std::max(peak, std::abs(v));
                    // The far part's FFT leaves round-off of about 1e-16 of the peak everywhere; a column keeps
                    // what is above 1e-12 of its own peak.
                    for (size_t i = 0; i < img.size(); ++i)
                        if (std::abs(img[i]) > 1e-12 * peak) {
                            out.pixels[j].push_back(static_cast<uint32_t>(base + i));
                            out.values[j].push_back(img[i]);
                        }
                }
            }
            projectionSeconds_ += secondsSince(start);
            ++projections_;
        }
    }
    return out;
}

std::vector<double> StackOperator::apply(const ParameterMap& map, const std::vector<double>& theta, bool withFixed) const {
    return applyParts(map, theta, withFixed, ProjectorParts::All);
}

std::vector<double> StackOperator::tail(const ParameterMap& map, const std::vector<double>& theta, bool withFixed) const {
    return applyParts(map, theta, withFixed, ProjectorParts::TailOnly);
}

std::vector<double> StackOperator::applyParts(const ParameterMap& map, const std::vector<double>& theta, bool withFixed, ProjectorParts parts) const {
    if (theta.size() != map.size()) throw ConfigError("stack operator: " + std::to_string(theta.size()) + " values for " + std::to_string(map.size()) + " parameters");
    std::vector<double> y(stackPixels(), 0.0);
    const size_t planePixels = static_cast<size_t>(width_) * height_;
    for (size_t slot = 0; slot < channels_.size(); ++slot) {
        const Channel& ch = *channels_[slot];
        if (!ch.lattice) continue;
        if (!ch.gains) throw ConfigError("stack operator: refresh the gains before applying it");
        for (int k = 0; k < planes_; ++k) {
            const auto start = std::chrono::steady_clock::now();
            PlaneTerms terms = planeTerms(*ch.imaging.unscattered, *ch.lattice, *ch.gains, ch.planeLights[static_cast<size_t>(k)],
                                          offsets_[static_cast<size_t>(k)], map, options_.threads, ch.fieldAt(k));
            for (size_t i = 0; i < terms.emissions.size(); ++i) {
                double c = 0;
                for (uint32_t e = terms.entryStart[i]; e < terms.entryStart[i + 1]; ++e) {
                    const ParameterMap::Entry& en = terms.entries[e];
                    if (en.parameter >= 0) c += en.coefficient * theta[static_cast<size_t>(en.parameter)];
                    else if (withFixed) c += en.coefficient;
                }
                terms.emissions[i].e *= c;
            }
            const std::vector<std::vector<double>> images =
                ch.imaging.unscattered->projector(offsets_[static_cast<size_t>(k)]).project(terms.emissions, 1, options_.threads, nullptr, parts);
            std::copy(images[0].begin(), images[0].end(), y.begin() + static_cast<std::ptrdiff_t>(planeImage(slot, k) * planePixels));
            projectionSeconds_ += secondsSince(start);
            ++projections_;
        }
    }
    return y;
}

std::vector<double> StackOperator::applyAdjoint(const ParameterMap& map, const std::vector<double>& y) const {
    if (y.size() != stackPixels()) throw ConfigError("stack operator: the adjoint needs " + std::to_string(stackPixels()) + " values, got " + std::to_string(y.size()));
    std::vector<double> out(map.size(), 0.0);
    const size_t planePixels = static_cast<size_t>(width_) * height_;
    for (size_t slot = 0; slot < channels_.size(); ++slot) {
        const Channel& ch = *channels_[slot];
        if (!ch.lattice) continue;
        if (!ch.gains) throw ConfigError("stack operator: refresh the gains before applying its adjoint");
        for (int k = 0; k < planes_; ++k) {
            const auto start = std::chrono::steady_clock::now();
            const PlaneTerms terms = planeTerms(*ch.imaging.unscattered, *ch.lattice, *ch.gains, ch.planeLights[static_cast<size_t>(k)],
                                                offsets_[static_cast<size_t>(k)], map, options_.threads, ch.fieldAt(k));
            const std::vector<double> image(y.begin() + static_cast<std::ptrdiff_t>(planeImage(slot, k) * planePixels),
                                            y.begin() + static_cast<std::ptrdiff_t>((planeImage(slot, k) + 1) * planePixels));
            const std::vector<double> sensitivity = ch.imaging.unscattered->projector(offsets_[static_cast<size_t>(k)]).backProject(image, terms.emissions, options_.threads);
            for (size_t i = 0; i < terms.emissions.size(); ++i)
                for (uint32_t e = terms.entryStart[i]; e < terms.entryStart[i + 1]; ++e) {
                    const ParameterMap::Entry& en = terms.entries[e];
                    if (en.parameter >= 0) out[static_cast<size_t>(en.parameter)] += sensitivity[i] * terms.emissions[i].e * en.coefficient;
                }
            projectionSeconds_ += secondsSince(start);
            ++projections_;
        }
    }
    return out;
}

std::vector<Medium> scaledMedia(const std::vector<Medium>& original, const ParameterMap& map, const std::vector<double>& theta,
                                const LatticeGeometry& frame) {
    if (theta.size() != map.size()) throw ConfigError("scaled media: " + std::to_string(theta.size()) + " values for " + std::to_string(map.size()) + " parameters");
    std::vector<Medium> out;
    for (size_t med = 0; med < original.size(); ++med) {
        const Medium& m = original[med];
        const VolumeFields* volume = m.volume();
        if (!volume) {
            const int param = map.parameterOf({static_cast<int32_t>(med), 0});
            if (param < 0 || map.isGrid()) {
                out.push_back(m);
                continue;
            }
            std::vector<DyeComponent> dyes = m.dyes();
            for (DyeComponent& d : dyes) d.molar *= theta[static_cast<size_t>(param)];
            out.emplace_back(m.name(), m.solventAbsorption(), m.scattering(), m.phase().g(), m.ior(), std::move(dyes));
            continue;
        }
        const DensityGrid* labels = volume->labels();
        const Affine toWorld = volume->worldFromIndex();
        auto scaled = volume->scaled([&](int channel, int i, int j, int k) {
            if (channel < kFirstDyeChannel) return 1.0;
            if (map.isGrid()) {
                const LatticeGeometry::Local q = frame.local(toWorld.apply(Vec3(i, j, k)));
                return map.gridFactor(q.x, q.y, q.z, theta);
            }
            const int32_t value = labels ? static_cast<int32_t>(labels->value(Vec3(i, j, k), Interpolation::Nearest)) : 0;
            const int param = map.parameterOf({static_cast<int32_t>(med), value});
            return param < 0 ? 1.0 : theta[static_cast<size_t>(param)];
        });
        out.push_back(m.withVolume(std::move(scaled)));
    }
    return out;
}

}  // namespace fluorosim::optics
