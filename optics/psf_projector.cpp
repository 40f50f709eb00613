#include "optics/psf_projector.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <numeric>

#include "core/errors.h"
#include "core/math.h"
#include "core/parallel.h"
#include "core/quadrature.h"
#include "optics/fft_convolution.h"

namespace fluorosim::optics {
namespace {

constexpr double kUmPerMm = 1e3;

int64_t floorDiv(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

double smoothStep01(double t) {
    t = std::clamp(t, 0.0, 1.0);
    return t * t * (3 - 2 * t);
}

// A position on a lattice of phases or layers: snapped to the node within round-off, so that a point
// on a node is split into one piece, not into a node and a neighbour of weight 1e-12.
double snapped(double x) {
    const double r = std::round(x);
    return std::abs(x - r) < 1e-7 ? r : x;
}

// A radial function tabulated on [0, rMax] at step dr, linearly interpolated, zero beyond.
struct RadialTable {
    double dr = 0;
    std::vector<double> v;
    template <class F>
    RadialTable(double rMax, double step, F&& f) : dr(step) {
        const size_t n = static_cast<size_t>(std::ceil(rMax / step)) + 2;
        v.resize(n);
        for (size_t i = 0; i < n; ++i) v[i] = f(static_cast<double>(i) * step);
    }
    double operator()(double r) const {
        const double u = r / dr;
        const size_t i = static_cast<size_t>(u);
        if (i + 1 >= v.size()) return 0.0;
        const double f = u - static_cast<double>(i);
        return v[i] + f * (v[i + 1] - v[i]);
    }
};

// Pixel-integrated values of a radial profile h(r) for a point at (fx, fy) in pixel 0 (pixel units), at
// pixel offsets within ±radius, by Gauss–Legendre points per pixel axis.
void integratePixels(const RadialTable& radial, double fx, double fy, int radius, const QuadratureRule& q, double pixelMm, float* out) {
    const int side = 2 * radius + 1;
    for (int dy = -radius; dy <= radius; ++dy)
        for (int dx = -radius; dx <= radius; ++dx) {
            double sum = 0;
            for (size_t a = 0; a < q.nodes.size(); ++a)
                for (size_t b = 0; b < q.nodes.size(); ++b) {
                    const double ux = dx + q.nodes[a] - fx, uy = dy + q.nodes[b] - fy;
                    sum += q.weights[a] * q.weights[b] * radial(std::sqrt(ux * ux + uy * uy) * pixelMm);
                }
            out[static_cast<size_t>(dy + radius) * side + (dx + radius)] = static_cast<float>(sum * pixelMm * pixelMm);
        }
}

// image rows += weight × kernel rows: the splat that is most of the computed image's time. Also built for
// AVX2 (without FMA: a product and a sum, rounded each, so every build adds the same bits).
__attribute__((target_clones("avx2", "default"))) void addScaledRows(double* __restrict image, int64_t imageStride, const float* __restrict kernel,
                                                                    int64_t kernelStride, int64_t rows, int64_t columns, double weight) {
    for (int64_t y = 0; y < rows; ++y) {
        double* __restrict r = image + y * imageStride;
        const float* __restrict k = kernel + y * kernelStride;
        for (int64_t x = 0; x < columns; ++x) r[x] += weight * static_cast<double>(k[x]);
    }
}

}  // namespace

struct PsfProjector::Impl {
    ProjectorOptions o;
    ProjectorGeometry g;
    std::shared_ptr<const WidefieldPsf> psf;
    std::vector<EmittingDye> dyes;  // their spectral nodes
    int pixelNodes = 3;
    int bins = 1;
    double halfDepthMm = 0;
    std::vector<double> splitInnerMm;  // per bin
    std::vector<int> layerBin;
    struct PhaseKernel {
        int radius = 0;
        std::vector<float> values;
    };
    mutable std::vector<std::unique_ptr<RadialTable>> radials;  // [dye × layers + layer]
    mutable std::unique_ptr<std::once_flag[]> radialBuilt;
    mutable std::vector<PhaseKernel> kernels;  // [(dye × layers + layer) F² + phaseY F + phaseX]
    mutable std::unique_ptr<std::once_flag[]> kernelBuilt;
    mutable std::atomic<int64_t> kernelNanoseconds{0};
    std::unique_ptr<FftConvolution> far;  // one kernel per dye and bin: dye × bins + bin
    int farRadius = 0;
    std::unique_ptr<FftConvolution> tail;  // on blocks, one kernel per dye and bin, like the far part
    int tailWidth = 0, tailHeight = 0;     // the region in blocks
    int reach = 0;

    int regionWidth() const { return g.width + 2 * g.marginPixels; }
    // Bilinear weights of a position x (pixels from the region's edge) on the block centres (B/2 + i B),
    // clamped at the edges: f(i, weight) twice.
    template <class F>
    void blockWeights(double x, int blocks, F&& f) const {
        const double c = x / o.tailBlockPixels - 0.5;
        const int i = static_cast<int>(std::floor(c));
        const double t = c - i;
        f(std::clamp(i, 0, blocks - 1), 1 - t);
        f(std::clamp(i + 1, 0, blocks - 1), t);
    }
    // The same in 2-D at (x, y): f(block index, weight) four times, rows outer.
    template <class F>
    void forEachBlock(double x, double y, F&& f) const {
        blockWeights(y, tailHeight, [&](int j, double wy) {
            blockWeights(x, tailWidth, [&](int i, double wx) { f(static_cast<size_t>(j) * tailWidth + static_cast<size_t>(i), wx * wy); });
        });
    }
    double binDz(int bin, double binMm) const { return -halfDepthMm + (bin + 0.5) * binMm; }
    size_t farIndex(uint32_t dye, int layer) const { return static_cast<size_t>(dye) * static_cast<size_t>(bins) + static_cast<size_t>(layerBin[static_cast<size_t>(layer)]); }
    int regionHeight() const { return g.height + 2 * g.marginPixels; }
    double layerDz(int l) const { return (l - 0.5 * g.layers + 0.5) * g.axialMm; }
    double taperMm() const { return o.nearTaperPixels * g.pixelMm; }
    double splitWeight(int bin, double rMm) const {  // 1 in the near part, 0 in the far part
        const double r1 = splitInnerMm[static_cast<size_t>(bin)], r2 = r1 + taperMm();
        return 1 - smoothStep01((rMm - r1) / (r2 - r1));
    }
    int kernelRadius(int layer) const {
        return static_cast<int>(std::ceil((splitInnerMm[static_cast<size_t>(layerBin[static_cast<size_t>(layer)])] + taperMm()) / g.pixelMm)) + 1;
    }
    double profile(const std::vector<double>& lambda, const std::vector<double>& weight, double rMm, double dzMm) const {
        double h = 0;
        for (size_t q = 0; q < lambda.size(); ++q) h += weight[q] * psf->density(rMm, dzMm, lambda[q]);
        return h;
    }
    const RadialTable& radial(size_t dye, int layer) const {
        const size_t index = dye * static_cast<size_t>(g.layers) + static_cast<size_t>(layer);
        std::call_once(radialBuilt[index], [&] {
            const EmittingDye& t = dyes[dye];
            const int bin = layerBin[static_cast<size_t>(layer)];
            const double dz = layerDz(layer);
            radials[index] = std::make_unique<RadialTable>((kernelRadius(layer) + 2) * g.pixelMm * std::sqrt(2.0), g.pixelMm / 64,
                                                           [&](double r) { return profile(t.nodeLambda, t.nodeWeight, r, dz) * splitWeight(bin, r); });
        });
        return *radials[index];
    }
    const PhaseKernel& kernel(size_t dye, int layer, int phaseX, int phaseY) const {
        const int F = o.kernelPhases;
        const size_t index = (dye * static_cast<size_t>(g.layers) + static_cast<size_t>(layer)) * static_cast<size_t>(F * F) +
                             static_cast<size_t>(phaseY) * F + static_cast<size_t>(phaseX);
        std::call_once(kernelBuilt[index], [&] {
            const auto start = std::chrono::steady_clock::now();
            PhaseKernel k;
            k.radius = kernelRadius(layer);
            const int side = 2 * k.radius + 1;
            k.values.resize(static_cast<size_t>(side) * side);
            // Mirrors and the transpose of a canonical phase (x ≤ F/2, y ≤ F/2, x ≤ y) are copies: a point at
            // phase f sees pixel offset d as a point at phase 1 − f sees −d.
            auto copyFrom = [&](const PhaseKernel& c, bool mirrorX, bool mirrorY, bool transpose) {
                for (int dy = -k.radius; dy <= k.radius; ++dy)
                    for (int dx = -k.radius; dx <= k.radius; ++dx) {
                        int sx = mirrorX ? -dx : dx, sy = mirrorY ? -dy : dy;
                        if (transpose) std::swap(sx, sy);
                        k.values[static_cast<size_t>(dy + k.radius) * side + (dx + k.radius)] =
                            c.values[static_cast<size_t>(sy + k.radius) * side + (sx + k.radius)];
                    }
            };
            if (phaseX > F / 2) copyFrom(kernel(dye, layer, F - phaseX, phaseY), true, false, false);
            else if (phaseY > F / 2) copyFrom(kernel(dye, layer, phaseX, F - phaseY), false, true, false);
            else if (phaseX > phaseY) copyFrom(kernel(dye, layer, phaseY, phaseX), false, false, true);
            else {
                const RadialTable& r = radial(dye, layer);
                integratePixels(r, double(phaseX) / F, double(phaseY) / F, k.radius, gaussLegendre01(pixelNodes), g.pixelMm, k.values.data());
            }
            kernels[index] = std::move(k);
            kernelNanoseconds += std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - start).count();
        });
        return kernels[index];
    }

    // The pieces of an emission: up to 2 layers × 4 phase corners, each a kernel near the point and a
    // bilinear deposit at the pixel centres for the far part.
    template <class F>
    void forEachPiece(const PointEmission& em, F&& f) const {
        const int F_ = o.kernelPhases;
        const double layerPos = snapped(std::clamp(em.layer, 0.0, double(g.layers - 1)));
        const int l0 = std::clamp(static_cast<int>(std::floor(layerPos)), 0, g.layers - 1), l1 = std::min(l0 + 1, g.layers - 1);
        const double fl = std::clamp(layerPos - l0, 0.0, 1.0);
        const double pu = snapped(em.u * F_), pv = snapped(em.v * F_);
        const int64_t iu = static_cast<int64_t>(std::floor(pu)), iv = static_cast<int64_t>(std::floor(pv));
        const double fu = pu - static_cast<double>(iu), fv = pv - static_cast<double>(iv);
        for (int dl = 0; dl < 2; ++dl) {
            const double wl = dl ? fl : 1 - fl;
            if (!(wl > 0)) continue;
            const int layer = dl ? l1 : l0;
            for (int corner = 0; corner < 4; ++corner) {
                const double wc = ((corner & 1) ? fu : 1 - fu) * ((corner & 2) ? fv : 1 - fv) * wl;
                if (!(wc > 0)) continue;
                const int64_t qu = iu + (corner & 1), qv = iv + ((corner >> 1) & 1);
                f(layer, qu, qv, wc);
            }
        }
    }
};

PsfProjector::PsfProjector(const ChannelDyes& dyes, std::shared_ptr<const WidefieldPsf> psf, const ProjectorGeometry& geometry, int pixelNodes,
                           const ProjectorOptions& options)
    : impl_(std::make_unique<Impl>()) {
    Impl& m = *impl_;
    m.o = options;
    m.g = geometry;
    m.psf = std::move(psf);
    m.dyes = dyes.dyes;
    m.pixelNodes = pixelNodes;
    if (m.g.layers < 2 || m.g.layers % 2) throw ConfigError("PSF projector: a plane needs an even number of layers, got " + std::to_string(m.g.layers));
    m.halfDepthMm = 0.5 * m.g.layers * m.g.axialMm;
    double lambdaMax = 0;
    for (const EmittingDye& t : m.dyes)
        for (double l : t.nodeLambda) lambdaMax = std::max(lambdaMax, l);
    const double cutMm = m.psf->cutRadiusMm(lambdaMax);

    // Far-field bins along dz; within a bin every layer splits near and far at the same radius, beyond
    // the widest defocus disc of the bin.
    m.bins = std::max(1, static_cast<int>(std::ceil(2 * m.halfDepthMm / (m.o.farBinUm / kUmPerMm))));
    const double binMm = 2 * m.halfDepthMm / m.bins;
    m.splitInnerMm.assign(static_cast<size_t>(m.bins), 0.0);
    for (int b = 0; b < m.bins; ++b) {
        const double binLo = -m.halfDepthMm + b * binMm, binHi = binLo + binMm;
        const double widest = std::max(std::abs(binLo), std::abs(binHi));
        m.splitInnerMm[static_cast<size_t>(b)] = (m.o.nearPixels + std::ceil(widest * m.g.tanThetaMax / m.g.pixelMm)) * m.g.pixelMm;
    }
    m.layerBin.resize(static_cast<size_t>(m.g.layers));
    for (int l = 0; l < m.g.layers; ++l)
        m.layerBin[static_cast<size_t>(l)] = std::clamp(static_cast<int>((m.layerDz(l) + m.halfDepthMm) / binMm), 0, m.bins - 1);
    m.radials.resize(m.dyes.size() * static_cast<size_t>(m.g.layers));
    m.radialBuilt = std::make_unique<std::once_flag[]>(m.radials.size());
    m.kernels.resize(m.radials.size() * static_cast<size_t>(m.o.kernelPhases * m.o.kernelPhases));
    m.kernelBuilt = std::make_unique<std::once_flag[]>(m.kernels.size());
    for (double r : m.splitInnerMm) m.reach = std::max(m.reach, static_cast<int>(std::ceil((r + m.taperMm()) / m.g.pixelMm)) + 2);

    // Far kernels: each dye's polychromatic PSF beyond the split, for a point at a pixel centre, one per
    // dye and bin (the FFTs of a dye that emits nowhere in a bin are skipped).
    m.farRadius = static_cast<int>(std::ceil(cutMm / m.g.pixelMm)) + 2;
    m.far = std::make_unique<FftConvolution>(m.regionWidth(), m.regionHeight(), m.farRadius);
    const QuadratureRule q = gaussLegendre01(m.pixelNodes);
    const int side = 2 * m.farRadius + 1;
    for (const EmittingDye& t : m.dyes)
        for (int b = 0; b < m.bins; ++b) {
            const double dz = m.binDz(b, binMm);
            const RadialTable radial((m.farRadius + 2) * m.g.pixelMm * std::sqrt(2.0), m.g.pixelMm / 16,
                                     [&](double r) { return m.profile(t.nodeLambda, t.nodeWeight, r, dz) * (1 - m.splitWeight(b, r)); });
            std::vector<float> k(static_cast<size_t>(side) * side);
            integratePixels(radial, 0.5, 0.5, m.farRadius, q, m.g.pixelMm, k.data());
            m.far->addKernel(std::vector<double>(k.begin(), k.end()));
        }

    // Tail kernels: per dye and bin, the light beyond the table's cut, (1 − enclosed) vCut / (2π v³) per
    // unit v-area at each wavelength node, integrated over each block (a source at a block's centre).
    if (m.o.tailBlockPixels > 0) {
        const int B = m.o.tailBlockPixels;
        m.tailWidth = (m.regionWidth() + B - 1) / B;
        m.tailHeight = (m.regionHeight() + B - 1) / B;
        const int tailRadius = static_cast<int>(std::ceil(std::hypot(m.tailWidth, m.tailHeight))) + 1;
        m.tail = std::make_unique<FftConvolution>(m.tailWidth, m.tailHeight, tailRadius);
        const double blockMm = B * m.g.pixelMm, vCut = m.psf->table().vCut;
        const int tside = 2 * tailRadius + 1;
        double cutMin = 1e300, cutMax = 0;  // the cut radii over the dyes' nodes
        for (const EmittingDye& t : m.dyes)
            for (double l : t.nodeLambda) {
                cutMin = std::min(cutMin, m.psf->cutRadiusMm(l));
                cutMax = std::max(cutMax, m.psf->cutRadiusMm(l));
            }
        for (const EmittingDye& t : m.dyes)
            for (int b = 0; b < m.bins; ++b) {
                const double dz = m.binDz(b, binMm);
                std::vector<double> kna(t.nodeLambda.size()), amplitude(t.nodeLambda.size());
                for (size_t n = 0; n < t.nodeLambda.size(); ++n) {
                    kna[n] = 2 * kPi / (t.nodeLambda[n] * 1e-6) * m.psf->pupil().na;
                    amplitude[n] = t.nodeWeight[n] * std::max(0.0, 1 - m.psf->enclosed(dz, t.nodeLambda[n])) * vCut / (2 * kPi);
                }
                const RadialTable density((tailRadius + 2) * blockMm * std::sqrt(2.0), m.g.pixelMm / 8, [&](double r) {
                    double d = 0;
                    for (size_t n = 0; n < kna.size(); ++n) {
                        const double v = kna[n] * r;
                        if (v > vCut) d += amplitude[n] * kna[n] * kna[n] / (v * v * v);
                    }
                    return d;
                });
                std::vector<double> k(static_cast<size_t>(tside) * tside, 0.0);
                parallelFor(static_cast<size_t>(tside), 0, [&](size_t row) {
                    const int dy = static_cast<int>(row) - tailRadius;
                    for (int dx = -tailRadius; dx <= tailRadius; ++dx) {
                        // Nothing within the cut; midpoint nodes 2 per pixel where a block straddles it, 4 per block
                        // where 1/r³ is smooth (a block's corners lie within 0.71 blocks of its centre).
                        const double d = std::sqrt(double(dx * dx + dy * dy));
                        if ((d + 0.75) * blockMm < cutMin) continue;
                        const int sub = (d - 0.75) * blockMm <= cutMax ? 2 * B : 4;
                        double sum = 0;
                        for (int a = 0; a < sub; ++a)
                            for (int c = 0; c < sub; ++c) {
                                const double x = (dx + (a + 0.5) / sub - 0.5) * blockMm, y = (dy + (c + 0.5) / sub - 0.5) * blockMm;
                                sum += density(std::sqrt(x * x + y * y));
                            }
                        k[static_cast<size_t>(dy + tailRadius) * tside + static_cast<size_t>(dx + tailRadius)] = sum * sqr(blockMm / sub);
                    }
                });
                m.tail->addKernel(k);
            }
    }
}

PsfProjector::~PsfProjector() = default;
const ProjectorGeometry& PsfProjector::geometry() const { return impl_->g; }
int PsfProjector::reachPixels() const { return impl_->reach; }
double PsfProjector::kernelSeconds() const { return 1e-9 * static_cast<double>(impl_->kernelNanoseconds.load()); }

std::vector<std::vector<double>> PsfProjector::project(const std::vector<PointEmission>& emissions, int targets, int threads,
                                                       const std::atomic<bool>* cancel, ProjectorParts parts) const {
    const Impl& m = *impl_;
    const bool nearAndFar = parts != ProjectorParts::TailOnly, withTail = parts != ProjectorParts::WithoutTail && m.tail;
    const int F = m.o.kernelPhases, W = m.regionWidth(), H = m.regionHeight();
    const int width = m.g.width, height = m.g.height, margin = m.g.marginPixels;
    std::vector<std::vector<double>> out(static_cast<size_t>(std::max(0, targets)), std::vector<double>(static_cast<size_t>(width) * height, 0.0));
    constexpr int kBandRows = 48;
    const int bands = (H + kBandRows - 1) / kBandRows;
    // Emissions by row, stable (each pixel adds its emissions in the caller's order within a row), by a
    // counting sort on rows clamped to those the bands read: a band of rows [y0, y1) reads the emissions
    // of rows [y0 − reach − 1, y1 + reach].
    const int64_t rowLo = -static_cast<int64_t>(m.reach) - 1, rowHi = static_cast<int64_t>(H) + m.reach;
    std::vector<int64_t> row(emissions.size());
    std::vector<uint32_t> rowStart(static_cast<size_t>(rowHi - rowLo + 2), 0u);
    for (size_t i = 0; i < emissions.size(); ++i) {
        row[i] = std::clamp(static_cast<int64_t>(std::floor(emissions[i].v)), rowLo, rowHi);
        ++rowStart[static_cast<size_t>(row[i] - rowLo + 1)];
    }
    for (size_t r = 1; r < rowStart.size(); ++r) rowStart[r] += rowStart[r - 1];
    std::vector<uint32_t> order(emissions.size());
    {
        std::vector<uint32_t> next(rowStart.begin(), rowStart.end() - 1);
        for (size_t i = 0; i < emissions.size(); ++i) order[next[static_cast<size_t>(row[i] - rowLo)]++] = static_cast<uint32_t>(i);
    }
    // The emissions whose rows a band owns: [y0, y1), the first band also those above, the last those below.
    const auto owned = [&](int band) {
        const int64_t lo = band == 0 ? rowLo : int64_t(band) * kBandRows, hi = band == bands - 1 ? rowHi + 1 : std::min<int64_t>(H, int64_t(band + 1) * kBandRows);
        return std::make_pair(order.begin() + rowStart[static_cast<size_t>(lo - rowLo)], order.begin() + rowStart[static_cast<size_t>(hi - rowLo)]);
    };
    const size_t farCount = static_cast<size_t>(m.far->kernelCount());
    const size_t blocks = withTail ? static_cast<size_t>(m.tailWidth) * m.tailHeight : 0;
    // Targets in batches, so that the far bins of many targets (per-label columns) fit in memory.
    const int batch = std::max(1, std::min(targets, 8));
    for (int t0 = 0; t0 < targets; t0 += batch) {
        const int t1 = std::min(targets, t0 + batch);
        const auto inBatch = [&](const PointEmission& em) { return static_cast<int>(em.target) >= t0 && static_cast<int>(em.target) < t1 && em.e != 0; };
        // Per band: which far bins its emissions use, and the tail's block deposits (summed over the bands
        // in order afterwards, so the sums do not depend on the threads).
        std::vector<std::vector<uint8_t>> bandUses(static_cast<size_t>(bands), std::vector<uint8_t>(static_cast<size_t>(t1 - t0) * farCount, 0));
        std::vector<std::vector<std::vector<double>>> bandTail(static_cast<size_t>(bands));
        parallelFor(static_cast<size_t>(bands), threads, [&](size_t band) {
            if (withTail) bandTail[band].resize(static_cast<size_t>(t1 - t0) * farCount);
            const auto [begin, end] = owned(static_cast<int>(band));
            for (auto it = begin; it != end; ++it) {
                const PointEmission& em = emissions[*it];
                if (!inBatch(em)) continue;
                const size_t base = static_cast<size_t>(static_cast<int>(em.target) - t0) * farCount;
                m.forEachPiece(em, [&](int layer, int64_t qu, int64_t qv, double wc) {
                    const size_t bin = base + m.farIndex(em.dye, layer);
                    bandUses[band][bin] = 1;
                    if (!withTail) return;
                    std::vector<double>& tail = bandTail[band][bin];
                    if (tail.empty()) tail.assign(blocks, 0.0);
                    m.forEachBlock(double(qu) / F, double(qv) / F, [&](size_t block, double w) { tail[block] += em.e * wc * w; });
                });
            }
        });
        std::vector<std::vector<std::vector<double>>> farBins(static_cast<size_t>(t1 - t0), std::vector<std::vector<double>>(farCount));
        std::vector<std::vector<std::vector<double>>> tailBins(static_cast<size_t>(t1 - t0), std::vector<std::vector<double>>(withTail ? farCount : 0));
        for (size_t ti = 0; ti < farBins.size(); ++ti)
            for (size_t bin = 0; bin < farCount; ++bin)
                for (int band = 0; band < bands; ++band) {
                    if (!bandUses[static_cast<size_t>(band)][ti * farCount + bin]) continue;
                    if (nearAndFar && farBins[ti][bin].empty()) farBins[ti][bin].assign(static_cast<size_t>(W) * H, 0.0);
                    if (!withTail) continue;
                    std::vector<double>& tail = tailBins[ti][bin];
                    const std::vector<double>& part = bandTail[static_cast<size_t>(band)][ti * farCount + bin];
                    if (tail.empty()) tail.assign(blocks, 0.0);
                    for (size_t k = 0; k < blocks; ++k) tail[k] += part[k];
                }
        bandTail = {};
        if (nearAndFar) parallelFor(static_cast<size_t>(bands), threads, [&](size_t band) {
            if (cancel && cancel->load()) return;
            const int y0 = static_cast<int>(band) * kBandRows, y1 = std::min(H, y0 + kBandRows);
            const auto first = order.begin() + rowStart[static_cast<size_t>(std::max(rowLo, int64_t(y0) - m.reach - 1) - rowLo)];
            const auto last = order.begin() + rowStart[static_cast<size_t>(std::min(rowHi, int64_t(y1) + m.reach) - rowLo + 1)];
            for (auto it = first; it != last; ++it) {
                const PointEmission& em = emissions[*it];
                if (!inBatch(em)) continue;
                double* image = out[em.target].data();
                auto& bins = farBins[static_cast<size_t>(static_cast<int>(em.target) - t0)];
                m.forEachPiece(em, [&](int layer, int64_t qu, int64_t qv, double wc) {
                    const int64_t px = floorDiv(qu, F), py = floorDiv(qv, F);
                    const int phx = static_cast<int>(qu - px * F), phy = static_cast<int>(qv - py * F);
                    const double weight = em.e * wc;
                    const auto& k = m.kernel(em.dye, layer, phx, phy);
                    const int side = 2 * k.radius + 1;
                    // The near part only where the camera is (the far part reaches the whole region).
                    const int64_t xa = std::max<int64_t>(margin, px - k.radius), xb = std::min<int64_t>(margin + width, px + k.radius + 1);
                    const int64_t ya = std::max<int64_t>(std::max(y0, margin), py - k.radius), yb = std::min<int64_t>(std::min(y1, margin + height), py + k.radius + 1);
                    if (ya < yb && xa < xb)
                        addScaledRows(image + static_cast<size_t>(ya - margin) * width + (xa - margin), width,
                                      k.values.data() + static_cast<size_t>(ya - py + k.radius) * side + (xa - px + k.radius), side, yb - ya, xb - xa, weight);
                    // The far part: bilinear deposits at the four pixel centres around the node.
                    const double cu = double(qu) / F - 0.5, cv = double(qv) / F - 0.5;
                    const int64_t cx = static_cast<int64_t>(std::floor(cu)), cy = static_cast<int64_t>(std::floor(cv));
                    const double gx = cu - static_cast<double>(cx), gy = cv - static_cast<double>(cy);
                    std::vector<double>& bin = bins[m.farIndex(em.dye, layer)];
                    for (int q = 0; q < 4; ++q) {
                        const int64_t x = cx + (q & 1), y = cy + ((q >> 1) & 1);
                        if (x < 0 || x >= W || y < y0 || y >= y1) continue;
                        bin[static_cast<size_t>(y) * W + static_cast<size_t>(x)] += weight * ((q & 1) ? gx : 1 - gx) * ((q & 2) ? gy : 1 - gy);
                    }
                });
            }
        });
        if (cancel && cancel->load()) return {};
        parallelFor(static_cast<size_t>(t1 - t0), threads, [&](size_t ti) {
            std::vector<double>& image = out[static_cast<size_t>(t0) + ti];
            if (nearAndFar) {
                const std::vector<double> farImage = m.far->convolveSum(farBins[ti]);
                for (int y = 0; y < height; ++y)
                    for (int x = 0; x < width; ++x)
                        image[static_cast<size_t>(y) * width + x] += farImage[static_cast<size_t>(y + margin) * W + static_cast<size_t>(x + margin)];
            }
            if (!withTail) return;
            // Each block holds the tail's photoelectrons over its B² pixels: interpolated bilinearly per pixel.
            const std::vector<double> tailImage = m.tail->convolveSum(tailBins[ti]);
            const double perPixel = 1.0 / sqr(static_cast<double>(m.o.tailBlockPixels));
            for (int y = 0; y < height; ++y)
                for (int x = 0; x < width; ++x) {
                    double sum = 0;
                    m.forEachBlock(x + margin + 0.5, y + margin + 0.5, [&](size_t block, double w) { sum += w * tailImage[block]; });
                    image[static_cast<size_t>(y) * width + x] += sum * perPixel;
                }
        });
    }
    return out;
}

std::vector<double> PsfProjector::backProject(const std::vector<double>& image, const std::vector<PointEmission>& emissions, int threads) const {
    const Impl& m = *impl_;
    const int F = m.o.kernelPhases, W = m.regionWidth(), H = m.regionHeight();
    const int width = m.g.width, height = m.g.height, margin = m.g.marginPixels;
    if (image.size() != static_cast<size_t>(width) * height)
        throw ConfigError("PSF projector: the adjoint needs a " + std::to_string(width) + " x " + std::to_string(height) + " image, got " +
                          std::to_string(image.size()) + " values");
    // The far part's adjoint: the camera image in the region, correlated with each bin's kernel.
    std::vector<double> region(static_cast<size_t>(W) * H, 0.0);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) region[static_cast<size_t>(y + margin) * W + static_cast<size_t>(x + margin)] = image[static_cast<size_t>(y) * width + x];
    const size_t farCount = static_cast<size_t>(m.far->kernelCount());
    std::vector<uint8_t> binUsed(farCount, 0);
    for (const PointEmission& em : emissions)
        m.forEachPiece(em, [&](int layer, int64_t, int64_t, double) { binUsed[m.farIndex(em.dye, layer)] = 1; });
    std::vector<std::vector<double>> farAdjoint(farCount);
    parallelFor(farCount, threads, [&](size_t b) {
        if (binUsed[b]) farAdjoint[b] = m.far->correlate(region, static_cast<int>(b));
    });
    // The tail's adjoint: the camera image gathered onto blocks (the transposed interpolation), correlated.
    std::vector<std::vector<double>> tailAdjoint(farCount);
    if (m.tail) {
        std::vector<double> blocks(static_cast<size_t>(m.tailWidth) * m.tailHeight, 0.0);
        const double perPixel = 1.0 / sqr(static_cast<double>(m.o.tailBlockPixels));
        for (int y = 0; y < height; ++y)
            for (int x = 0; x < width; ++x) {
                const double value = image[static_cast<size_t>(y) * width + x] * perPixel;
                m.forEachBlock(x + margin + 0.5, y + margin + 0.5, [&](size_t block, double w) { blocks[block] += w * value; });
            }
        parallelFor(farCount, threads, [&](size_t b) {
            if (binUsed[b]) tailAdjoint[b] = m.tail->correlate(blocks, static_cast<int>(b));
        });
    }
    std::vector<double> out(emissions.size(), 0.0);
    parallelFor(emissions.size(), threads, [&](size_t i) {
        const PointEmission& em = emissions[i];
        double sum = 0;
        m.forEachPiece(em, [&](int layer, int64_t qu, int64_t qv, double wc) {
            const int64_t px = floorDiv(qu, F), py = floorDiv(qv, F);
            const int phx = static_cast<int>(qu - px * F), phy = static_cast<int>(qv - py * F);
            const auto& k = m.kernel(em.dye, layer, phx, phy);
            const int side = 2 * k.radius + 1;
            const int64_t xa = std::max<int64_t>(margin, px - k.radius), xb = std::min<int64_t>(margin + width, px + k.radius + 1);
            double near = 0;
            for (int64_t y = std::max<int64_t>(margin, py - k.radius); y < std::min<int64_t>(margin + height, py + k.radius + 1); ++y) {
                const double* r = image.data() + static_cast<size_t>(y - margin) * width + (xa - margin);
                const float* kr = k.values.data() + static_cast<size_t>(y - py + k.radius) * side + (xa - px + k.radius);
                for (int64_t x = 0; x < xb - xa; ++x) near += r[x] * kr[x];
            }
            const double cu = double(qu) / F - 0.5, cv = double(qv) / F - 0.5;
            const int64_t cx = static_cast<int64_t>(std::floor(cu)), cy = static_cast<int64_t>(std::floor(cv));
            const double gx = cu - static_cast<double>(cx), gy = cv - static_cast<double>(cy);
            const std::vector<double>& adj = farAdjoint[m.farIndex(em.dye, layer)];
            double far = 0;
            for (int q = 0; q < 4; ++q) {
                const int64_t x = cx + (q & 1), y = cy + ((q >> 1) & 1);
                if (x < 0 || x >= W || y < 0 || y >= H) continue;
                far += adj[static_cast<size_t>(y) * W + static_cast<size_t>(x)] * ((q & 1) ? gx : 1 - gx) * ((q & 2) ? gy : 1 - gy);
            }
            double tail = 0;
            if (m.tail) {
                const std::vector<double>& adjTail = tailAdjoint[m.farIndex(em.dye, layer)];
                m.forEachBlock(double(qu) / F, double(qv) / F, [&](size_t block, double w) { tail += w * adjTail[block]; });
            }
            sum += wc * (near + far + tail);
        });
        out[i] = sum;
    });
    return out;
}

}  // namespace fluorosim::optics
