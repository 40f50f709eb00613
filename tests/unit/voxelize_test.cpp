// Voxelization of neuron morphologies: partial-volume coverage against closed forms (sphere,
// capsule, membrane shells), the acceptance test (covered volume within 3 % of the
// analytic volume at a voxel of a fifth of the median radius, on a synthetic and on real
// morphologies), the VDB file's grids, metadata and labels, and the `voxelize` command.
#include <gtest/gtest.h>

#include "support/cli_runner.h"
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/rng.h"
#include "morphology/swc.h"
#include "volume/voxelize.h"

namespace fluorosim {
namespace {

namespace fs = std::filesystem;
constexpr double kPi = std::numbers::pi;

// ---- helpers ----

double sphereVolume(double r) { return 4.0 / 3.0 * kPi * r * r * r; }

NeuronVolumeInput input(Morphology m, const std::string& grid = "dye", double concentration = 10, int label = 1) {
    NeuronVolumeInput n;
    n.morphology = std::move(m);
    n.gridName = grid;
    n.concentration = concentration;
    n.units = "uM";
    n.label = label;
    return n;
}

VoxelizeOptions options(double voxelUm, LabelMode mode = LabelMode::Filled) {
    VoxelizeOptions o;
    o.voxelSizeMm = voxelUm * 1e-3;
    o.mode = mode;
    return o;
}

double coveredUm3(const Morphology& m, const VoxelizeOptions& o) { return voxelizeNeurons({input(m)}, o).neurons.at(0).coveredVolumeUm3; }

// Supersampling counts sub-voxel centres (spacing δ = voxel / k) inside the shape. Each sub-cell cut
// by the surface errs by (inside? 1 : 0) - (its fraction inside), mean ≈ 0 and variance ≈ 1/6 of a
// sub-cell volume squared; about 1.5 A / δ² sub-cells are cut (mean width of a cube 1.5 δ), so
// σ(V) ≈ δ² √A / 2. The tolerance is 6 σ: far beyond chance, tight enough to catch any bias.
double samplingTolerance(double areaUm2, double voxelUm, int k = 4) {
    const double d = voxelUm / k;
    return 6 * d * d * std::sqrt(areaUm2) / 2;
}

// A sample on its own line: id type x y z r parent.
std::string swcLine(int id, int type, const Vec3& p, double r, int parent) {
    std::ostringstream os;
    os.precision(17);
    os << id << " " << type << " " << p.x << " " << p.y << " " << p.z << " " << r << " " << parent << "\n";
    return os.str();
}

// A synthetic neuron: a soma of radius 4 µm and five dendrites, each a binary tree of depth 3 whose
// branches (two 5 µm segments with a small bend between them) taper from 0.8 to 0.3 µm. Fixed
// directions, no randomness.
Morphology syntheticNeuron() {
    std::string swc = swcLine(1, 1, Vec3(0.3, -0.2, 0.1), 4.0, -1);
    int next = 2;
    const Vec3 trunks[5] = {Vec3(1, 0.1, 0.2), Vec3(-0.3, 1, 0.1), Vec3(-0.8, -0.5, 0.3), Vec3(0.2, -0.7, -0.7), Vec3(0.1, 0.3, 1)};
    struct Branch {
        int parent;
        Vec3 start, dir;
        int depth;
    };
    std::deque<Branch> todo;
    for (const Vec3& t : trunks) {
        const Vec3 d = normalize(t);
        todo.push_back({1, Vec3(0.3, -0.2, 0.1) + d * 4.0, d, 0});
    }
    while (!todo.empty()) {
        const Branch b = todo.front();
        todo.pop_front();
        const double r0 = 0.8 - 0.15 * b.depth, r1 = r0 - 0.05, r2 = r0 - 0.1;
        // A point just outside the soma so the first segment is a short cylinder from its surface.
        int parent = b.parent;
        Vec3 p = b.start;
        if (b.depth == 0) {
            p = p + b.dir * 0.5;
            swc += swcLine(next, 3, p, r0, parent);
            parent = next++;
        }
        const Frame f = Frame::fromNormal(b.dir);
        const Vec3 bent = normalize(b.dir + f.s * 0.15);
        const Vec3 mid = p + b.dir * 5.0, end = mid + bent * 5.0;
        swc += swcLine(next, 3, mid, r1, parent);
        swc += swcLine(next + 1, 3, end, r2, next);
        const int tip = next + 1;
        next += 2;
        if (b.depth < 3)
            for (double side : {-1.0, 1.0}) todo.push_back({tip, end, normalize(bent + f.t * (0.6 * side) + f.s * 0.1), b.depth + 1});
    }
    return parseSwc(swc, "synthetic");
}

// The connected subtree of the first `maxSamples` samples reached breadth-first from `rootId`
// (children in file order), with the root made a root.
Morphology crop(const Morphology& m, int rootId, size_t maxSamples) {
    std::map<int, std::vector<size_t>> children;
    size_t root = m.samples.size();
    for (size_t i = 0; i < m.samples.size(); ++i) {
        children[m.samples[i].parent].push_back(i);
        if (m.samples[i].id == rootId) root = i;
    }
    Morphology out;
    out.source = m.source + " (crop)";
    std::deque<size_t> queue{root};
    while (!queue.empty() && out.samples.size() < maxSamples) {
        const size_t i = queue.front();
        queue.pop_front();
        out.samples.push_back(m.samples[i]);
        if (i == root) out.samples.back().parent = -1;
        for (size_t c : children[m.samples[i].id]) queue.push_back(c);
    }
    return out;
}

// ---- closed forms ----

TEST(Voxelize, SphereMatchesClosedForm) {
    const double r = 3.0, h = 0.2;
    const Morphology m = parseSwc(swcLine(1, 1, Vec3(0.37, -0.21, 0.05), r, -1), "sphere");
    const double v = coveredUm3(m, options(h));
    const double tol = samplingTolerance(4 * kPi * r * r, h);
    std::printf("  sphere r = %g um, voxel %g um: %.6f um^3, exact %.6f, error %.2e (tolerance %.2e)\n", r, h, v, sphereVolume(r),
                v / sphereVolume(r) - 1, tol / sphereVolume(r));
    EXPECT_NEAR(v, sphereVolume(r), tol);
}

TEST(Voxelize, CapsuleMatchesClosedForm) {
    // One segment between equal radii is a capsule: πr²L + (4/3)πr³.
    const double r = 0.5, h = 0.1;
    const Vec3 a(0.13, 0.07, -0.02), b(14.0, 5.0, 3.0);
    const double len = length(b - a);
    const Morphology m = parseSwc(swcLine(1, 3, a, r, -1) + swcLine(2, 3, b, r, 1), "capsule");
    const double exact = kPi * r * r * len + sphereVolume(r);
    const double v = coveredUm3(m, options(h));
    const double tol = samplingTolerance(2 * kPi * r * len + 4 * kPi * r * r, h);
    std::printf("  capsule r = %g um, L = %.3f um, voxel %g um: %.6f um^3, exact %.6f, error %.2e (tolerance %.2e)\n", r, len, h, v, exact,
                v / exact - 1, tol / exact);
    EXPECT_NEAR(v, exact, tol);
}

TEST(Voxelize, MembraneShellsMatchClosedForms) {
    const double h = 0.1, t = 0.3;
    {
        const double r = 3.0;
        const Morphology m = parseSwc(swcLine(1, 1, Vec3(0.37, -0.21, 0.05), r, -1), "sphere");
        VoxelizeOptions o = options(h, LabelMode::Membrane);
        o.membraneThicknessMm = t * 1e-3;
        const double exact = sphereVolume(r) - sphereVolume(r - t);
        const double v = coveredUm3(m, o);
        const double tol = samplingTolerance(4 * kPi * (r * r + (r - t) * (r - t)), h);
        std::printf("  sphere shell r = %g um, t = %g um: %.6f um^3, exact %.6f, error %.2e (tolerance %.2e)\n", r, t, v, exact, v / exact - 1,
                    tol / exact);
        EXPECT_NEAR(v, exact, tol);
    }
    {
        const double r = 1.0;
        const Vec3 a(0.13, 0.07, -0.02), b(20.0, 3.0, 1.0);
        const double len = length(b - a);
        const Morphology m = parseSwc(swcLine(1, 3, a, r, -1) + swcLine(2, 3, b, r, 1), "capsule");
        VoxelizeOptions o = options(h, LabelMode::Membrane);
        o.membraneThicknessMm = t * 1e-3;
        const double ri = r - t;
        const double exact = kPi * (r * r - ri * ri) * len + sphereVolume(r) - sphereVolume(ri);
        const double v = coveredUm3(m, o);
        const double tol = samplingTolerance(2 * kPi * (r + ri) * len + 4 * kPi * (r * r + ri * ri), h);
        std::printf("  capsule shell r = %g um, L = %.3f um, t = %g um: %.6f um^3, exact %.6f, error %.2e (tolerance %.2e)\n", r, len, t, v,
                    exact, v / exact - 1, tol / exact);
        EXPECT_NEAR(v, exact, tol);
    }
    {
        // The default thickness is one voxel.
        const double r = 2.0;
        const Morphology m = parseSwc(swcLine(1, 1, Vec3(0.37, -0.21, 0.05), r, -1), "sphere");
        const double exact = sphereVolume(r) - sphereVolume(r - h);
        const double v = coveredUm3(m, options(h, LabelMode::Membrane));
        EXPECT_NEAR(v, exact, samplingTolerance(4 * kPi * (r * r + (r - h) * (r - h)), h));
    }
}

// ---- acceptance: within 3 % of the analytic volume at voxel = median radius / 5 ----

void expectWithinThreePercent(const Morphology& m, const char* what) {
    const double h = medianRadiusUm(m) / 5;
    const auto start = std::chrono::steady_clock::now();
    const VoxelizeSummary s = voxelizeNeurons({input(m)}, options(h));
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double covered = s.neurons.at(0).coveredVolumeUm3, analytic = s.neurons.at(0).analyticVolumeUm3;
    std::printf("  %s: %zu samples, median radius %.4g um, voxel %.4g um: covered %.4f um^3, analytic %.4f um^3, difference %+.3f %% "
                "(%llu voxels, %.2f s)\n",
                what, m.samples.size(), medianRadiusUm(m), h, covered, analytic, 100 * (covered / analytic - 1),
                static_cast<unsigned long long>(s.grids.at(0).activeVoxels), seconds);
    EXPECT_NEAR(covered / analytic, 1.0, 0.03) << what;
}

TEST(Voxelize, SyntheticNeuronWithinThreePercent) { expectWithinThreePercent(syntheticNeuron(), "synthetic neuron"); }

// Whole real neurons at a fifth of their median radius take 20 s or more, so the test crops them
// to the 300 samples nearest the soma in the tree (breadth first), which keeps the soma with its
// primary branches, and to a 300-sample dendrite subtree without the soma, where the neurites'
// joints and tips are all of the volume.
TEST(Voxelize, RealNeuronsWithinThreePercent) {
    const std::string dir = FLUOROSIM_SOURCE_DIR "/samples/neurons/";
    const Morphology a = readSwc(dir + "C231296A-P3.CNG.swc");
    expectWithinThreePercent(crop(a, 1, 300), "C231296A-P3, 300 samples from the soma");
    const Morphology b = readSwc(dir + "C010398B-P2.CNG.swc");
    expectWithinThreePercent(crop(b, 1, 300), "C010398B-P2, 300 samples from the soma");
    // Sample 4 is the first apical sample after the 3-point soma.
    expectWithinThreePercent(crop(b, 4, 300), "C010398B-P2, apical subtree of 300 samples");
}


// ---- the covered volume is the union of the pieces ----

// Independent of the voxelizer's signed distance: a point lies in the hull of the balls (a, ra) and
// (b, rb) iff it lies in some ball (a + s(b - a), ra + s(rb - ra)), s in [0, 1]; the distance to
// the ball's surface is convex in s, so a ternary search finds its minimum.
bool insideHull(const MorphologyPiece& p, const Vec3& x) {
    auto g = [&](double s) { return length(x - (p.aUm + (p.bUm - p.aUm) * s)) - (p.raUm + s * (p.rbUm - p.raUm)); };
    if (p.sphere) return g(0) <= 0;
    double lo = 0, hi = 1;
    for (int i = 0; i < 60; ++i) {
        const double m1 = lo + (hi - lo) / 3, m2 = hi - (hi - lo) / 3;
        if (g(m1) < g(m2)) hi = m2;
        else lo = m1;
    }
    return std::min({g(0), g(1), g(0.5 * (lo + hi))}) <= 0;
}

struct UnionEstimate {
    double volume, stderr_;
};

// Monte Carlo volume of the union of the pieces: for each piece, uniform points in a box around it
// aligned with its axis, each inside point weighted by 1 / (number of pieces containing it), so
// every point of the union counts once. Unbiased, with its standard error.
UnionEstimate unionVolumeMonteCarlo(const std::vector<MorphologyPiece>& pieces, size_t points) {
    struct Box {
        Vec3 origin, e[3];
        double size[3], volume;
        Vec3 lo, hi;  // axis-aligned bounds of the piece
    };
    std::vector<Box> boxes;
    double total = 0;
    for (const MorphologyPiece& p : pieces) {
        Box b;
        const double r = std::max(p.raUm, p.rbUm);
        const double len = p.sphere ? 0 : length(p.bUm - p.aUm);
        const Vec3 u = len > 0 ? (p.bUm - p.aUm) / len : Vec3(0, 0, 1);
        const Frame f = Frame::fromNormal(u);
        b.e[0] = u, b.e[1] = f.s, b.e[2] = f.t;
        b.origin = p.aUm - u * r - f.s * r - f.t * r;
        b.size[0] = len + 2 * r, b.size[1] = b.size[2] = 2 * r;
        b.volume = b.size[0] * b.size[1] * b.size[2];
        for (int c = 0; c < 3; ++c) {
            b.lo[c] = std::min(p.aUm[c], p.bUm[c]) - r;
            b.hi[c] = std::max(p.aUm[c], p.bUm[c]) + r;
        }
        boxes.push_back(b);
        total += b.volume;
    }
    double volume = 0, variance = 0;
    for (size_t i = 0; i < pieces.size(); ++i) {
        const Box& b = boxes[i];
        const size_t n = std::max<size_t>(64, static_cast<size_t>(static_cast<double>(points) * b.volume / total));
        Rng rng = Rng::forKey(7, i, 0);
        double sum = 0, sum2 = 0;
        for (size_t k = 0; k < n; ++k) {
            const Vec3 x = b.origin + b.e[0] * (rng.uniform() * b.size[0]) + b.e[1] * (rng.uniform() * b.size[1]) +
                           b.e[2] * (rng.uniform() * b.size[2]);
            if (!insideHull(pieces[i], x)) continue;
            int cover = 0;
            for (size_t j = 0; j < pieces.size(); ++j) {
                const Box& o = boxes[j];
                if (x.x < o.lo.x || x.x > o.hi.x || x.y < o.lo.y || x.y > o.hi.y || x.z < o.lo.z || x.z > o.hi.z) continue;
                cover += j == i || insideHull(pieces[j], x);
            }
            const double w = b.volume / cover;
            sum += w;
            sum2 += w * w;
        }
        const double mean = sum / static_cast<double>(n);
        volume += mean;
        variance += (sum2 / static_cast<double>(n) - mean * mean) / static_cast<double>(n);
    }
    return {volume, std::sqrt(variance)};
}

// The difference between the covered and the analytic volume comes from the model, not from the
// voxelization: the frusta overlap at joints and branch points (counted twice by the analytic sum)
// and miss the round cones' end caps. A Monte Carlo estimate of the union agrees with the covered
// volume within its statistical error.
TEST(Voxelize, CoveredVolumeIsTheUnionOfThePieces) {
    const Morphology b = readSwc(FLUOROSIM_SOURCE_DIR "/samples/neurons/C010398B-P2.CNG.swc");
    const std::pair<Morphology, const char*> cases[] = {{syntheticNeuron(), "synthetic neuron"},
                                                        {crop(b, 4, 300), "C010398B-P2 apical subtree"}};
    for (const auto& [m, what] : cases) {
        const double h = medianRadiusUm(m) / 5;
        const VoxelizeSummary s = voxelizeNeurons({input(m)}, options(h));
        const double covered = s.neurons.at(0).coveredVolumeUm3, analytic = s.neurons.at(0).analyticVolumeUm3;
        const UnionEstimate u = unionVolumeMonteCarlo(morphologyPieces(m), 400000);
        std::printf("  %s: covered %.4f um^3, Monte Carlo union %.4f +- %.4f um^3 (z = %+.2f), analytic (frusta) %.4f um^3: union - analytic = %+.3f %%\n",
                    what, covered, u.volume, u.stderr_, (covered - u.volume) / u.stderr_, analytic, 100 * (u.volume / analytic - 1));
        // The voxelization's own sampling error is far below the Monte Carlo error here.
        EXPECT_NEAR(covered, u.volume, 5 * u.stderr_) << what;
    }
}

// ---- output file, grids, labels ----

// One folder per test process, removed at exit.
std::string tempPath(const std::string& name) {
    static const testing::TempDir dir;
    return dir.file(name).string();
}

const VdbGridStats& gridNamed(const std::vector<VdbGridStats>& grids, const std::string& name) {
    for (const auto& g : grids)
        if (g.name == name) return g;
    throw std::runtime_error("no grid " + name);
}

Morphology ball(const Vec3& c, double r, const std::string& name) { return parseSwc(swcLine(1, 1, c, r, -1), name); }

TEST(Voxelize, TwoDyesGiveTwoGridsAndLabels) {
    const double h = 0.25;
    std::vector<NeuronVolumeInput> in = {input(ball(Vec3(0, 0, 0), 2.0, "a"), "af488", 10, 1),
                                         input(ball(Vec3(10, 0, 0), 1.5, "b"), "af594", 5, 2)};
    in[0].dye = "alexa_fluor_488";
    in[1].dye = "alexa_fluor_594";
    const std::string out = tempPath("two.vdb");
    const VoxelizeSummary s = writeVoxelizedVdb(out, in, options(h));
    const auto grids = readVdbGridStats(out);
    fs::remove(out);
    ASSERT_EQ(grids.size(), 3u);
    ASSERT_EQ(s.grids.size(), 2u);
    const double voxelUm3 = h * h * h;
    for (size_t i = 0; i < 2; ++i) {
        const VdbGridStats& g = gridNamed(grids, in[i].gridName);
        EXPECT_EQ(g.valueType, "float");
        EXPECT_EQ(g.stringMetadata.at("units"), "uM");
        EXPECT_EQ(g.stringMetadata.at("length_unit"), "mm");
        EXPECT_EQ(g.stringMetadata.at("dye"), in[i].dye);
        EXPECT_TRUE(g.uniformScale);
        EXPECT_DOUBLE_EQ(g.voxelSizeMm, h * 1e-3);
        EXPECT_EQ(g.activeVoxels, s.grids[i].activeVoxels);
        EXPECT_FLOAT_EQ(static_cast<float>(g.max), static_cast<float>(in[i].concentration));
        EXPECT_GT(g.min, 0);
        // Values are concentration × coverage, so their sum is the covered volume in voxels.
        EXPECT_NEAR(g.sum * voxelUm3 / in[i].concentration, s.neurons[i].coveredVolumeUm3, 1e-5 * s.neurons[i].coveredVolumeUm3);
    }
    const VdbGridStats& label = gridNamed(grids, "label");
    EXPECT_EQ(label.valueType, "int32");
    EXPECT_EQ(label.stringMetadata.at("length_unit"), "mm");
    EXPECT_EQ(label.stringMetadata.at("label_2"), "b (grid af594)");
    ASSERT_EQ(label.int32Histogram.size(), 2u);
    EXPECT_EQ(label.activeVoxels, s.labelVoxels);
    // Every voxel a neuron covers at all carries its label (the two balls do not overlap), so each
    // label counts the voxels of its neuron's own grid.
    for (int l = 1; l <= 2; ++l)
        EXPECT_EQ(label.int32Histogram.at(l), gridNamed(grids, in[static_cast<size_t>(l - 1)].gridName).activeVoxels) << "label " << l;
}

TEST(Voxelize, NeuronsSharingAGridAddUp) {
    const double h = 0.25;
    // The same ball twice at 10 and 5 uM: the grid holds 15 uM inside, the label the first neuron.
    const std::vector<NeuronVolumeInput> in = {input(ball(Vec3(0.1, 0, 0), 2.0, "a"), "cells", 10, 1),
                                               input(ball(Vec3(0.1, 0, 0), 2.0, "b"), "cells", 5, 2)};
    const std::string out = tempPath("shared.vdb");
    const VoxelizeSummary s = writeVoxelizedVdb(out, in, options(h));
    const auto grids = readVdbGridStats(out);
    fs::remove(out);
    ASSERT_EQ(grids.size(), 2u);
    ASSERT_EQ(s.grids.size(), 1u);
    const VdbGridStats& g = gridNamed(grids, "cells");
    EXPECT_FLOAT_EQ(static_cast<float>(g.max), 15.0f);
    EXPECT_NEAR(g.sum * h * h * h, 15 * s.neurons[0].coveredVolumeUm3, 1e-5 * 15 * s.neurons[0].coveredVolumeUm3);
    EXPECT_DOUBLE_EQ(s.grids[0].coveredVolumeUm3, 2 * s.neurons[0].coveredVolumeUm3);
    const VdbGridStats& label = gridNamed(grids, "label");
    ASSERT_EQ(label.int32Histogram.size(), 1u);
    EXPECT_EQ(label.int32Histogram.begin()->first, 1);
}

TEST(Voxelize, ResultDoesNotDependOnThreads) {
    const Morphology m = syntheticNeuron();
    VoxelizeOptions one = options(0.2), two = options(0.2);
    one.threads = 1;
    two.threads = 2;
    const VoxelizeSummary a = voxelizeNeurons({input(m)}, one), b = voxelizeNeurons({input(m)}, two);
    EXPECT_EQ(a.neurons[0].coveredVolumeUm3, b.neurons[0].coveredVolumeUm3);
    EXPECT_EQ(a.grids[0].activeVoxels, b.grids[0].activeVoxels);
    EXPECT_EQ(a.labelVoxels, b.labelVoxels);
}

void expectConfigError(const std::function<void()>& f, const std::string& part) {
    try {
        f();
        ADD_FAILURE() << "expected ConfigError with \"" << part << "\"";
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
}

TEST(Voxelize, RejectsBadOptionsAndInputs) {
    const Morphology m = ball(Vec3(0, 0, 0), 2.0, "ball.swc");
    for (double v : {0.0, -1.0, std::nan(""), static_cast<double>(INFINITY)}) {
        VoxelizeOptions o = options(1);
        o.voxelSizeMm = v;
        expectConfigError([&] { voxelizeNeurons({input(m)}, o); }, "voxel size");
    }
    // A real neuron at 1 nm would need about 2e12 voxels: refused before any work.
    const Morphology real = readSwc(FLUOROSIM_SOURCE_DIR "/samples/neurons/C010398B-P2.CNG.swc");
    expectConfigError([&] { voxelizeNeurons({input(real)}, options(0.001)); }, "limit 4e9");
    VoxelizeOptions o = options(0.5, LabelMode::Membrane);
    o.membraneThicknessMm = -1e-3;
    expectConfigError([&] { voxelizeNeurons({input(m)}, o); }, "membrane thickness");
    o = options(0.5);
    o.supersampling = 0;
    expectConfigError([&] { voxelizeNeurons({input(m)}, o); }, "supersampling");
    expectConfigError([&] { voxelizeNeurons({input(m, "g", -1)}, options(0.5)); }, "concentration");
    expectConfigError([&] { voxelizeNeurons({input(m, "label")}, options(0.5)); }, "reserved");
    std::vector<NeuronVolumeInput> mixed = {input(m, "g"), input(m, "g", 10, 2)};
    mixed[1].units = "nM";
    expectConfigError([&] { voxelizeNeurons(mixed, options(0.5)); }, "\"nM\"");
    expectConfigError([&] { voxelizeNeurons({}, options(0.5)); }, "no neurons");
}

TEST(Voxelize, BlocksBeyondTheMemoryCapAreRefusedWhileCounting) {
    // A 1 km neurite of radius 0.1 um at 1 um voxels passes the volume check (about 3.8e9 voxels), but
    // its blocks used to take all memory in registerBlocks before failing with bad_alloc.
    struct CapGuard {
        CapGuard() { setMemoryCapBytes(uint64_t(64) << 20); }
        ~CapGuard() { setMemoryCapBytes(0); }
    } cap;
    const Morphology km = parseSwc(swcLine(1, 3, Vec3(0, 0, 0), 0.1, -1) + swcLine(2, 3, Vec3(1e9, 0, 0), 0.1, 1), "km.swc");
    expectConfigError([&] { voxelizeNeurons({input(km)}, options(1.0)); }, "memory cap of 64 MiB");
    expectConfigError([&] { voxelizeNeurons({input(km)}, options(1.0)); }, "km.swc");
    EXPECT_NO_THROW(voxelizeNeurons({input(syntheticNeuron())}, options(0.5)));
}

// ---- the voxelize command ----

// A folder and the voxelize command, through the shared CLI runner.
struct CliDir : testing::TempDir {
    testing::RunResult run(const std::vector<std::string>& args) const {
        std::vector<std::string> all{"voxelize"};
        all.insert(all.end(), args.begin(), args.end());
        return testing::runCli(*this, all);
    }
};
using CliRun = testing::RunResult;
using testing::contains;

TEST(VoxelizeCli, TwoNeuronsTwoDyes) {
    const CliDir dir;
    std::ostringstream syn;
    for (const SwcSample& s : syntheticNeuron().samples) syn << swcLine(s.id, s.type, s.positionUm, s.radiusUm, s.parent);
    const fs::path a = dir.write("synthetic.swc", syn.str());
    const std::string b = FLUOROSIM_SOURCE_DIR "/samples/neurons/mp_ma_40984_gc2.CNG.swc";
    const fs::path out = dir.path() / "cells.vdb";
    const CliRun r = dir.run({a.string(), b, "--voxel", "0.5um", "--dye", "AF488", "--dye", "mCherry", "--concentration", "10uM,2 µM",
                              "-o", out.string()});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_TRUE(contains(r.out, "grid alexa_fluor_488 [uM]")) << r.out;
    EXPECT_TRUE(contains(r.out, "grid mcherry [uM]")) << r.out;
    EXPECT_TRUE(contains(r.out, "grid label")) << r.out;
    EXPECT_TRUE(contains(r.out, "wrote " + out.string())) << r.out;
    const auto grids = readVdbGridStats(out.string());
    ASSERT_EQ(grids.size(), 3u);
    EXPECT_FLOAT_EQ(static_cast<float>(gridNamed(grids, "alexa_fluor_488").max), 10.0f);
    EXPECT_FLOAT_EQ(static_cast<float>(gridNamed(grids, "mcherry").max), 2.0f);
    EXPECT_EQ(gridNamed(grids, "label").int32Histogram.size(), 2u);

    // One grid for both, membrane labelling.
    const CliRun m = dir.run({a.string(), b, "--voxel", "0.5um", "--dye", "AF488", "--concentration", "1uM", "--grid", "cells", "--mode",
                              "membrane", "--membrane-thickness", "0.5um", "-o", out.string()});
    ASSERT_EQ(m.exitCode, 0) << m.err;
    EXPECT_TRUE(contains(m.out, "membrane")) << m.out;
    const auto shared = readVdbGridStats(out.string());
    ASSERT_EQ(shared.size(), 2u);
    EXPECT_EQ(gridNamed(shared, "cells").stringMetadata.at("mode"), "membrane");
}

// Two copies of one neuron in one grid overlap (twice the concentration) unless --offset places them
// apart; --rotate turns a neuron about its soma.
TEST(VoxelizeCli, OffsetAndRotationPlaceNeuronsApart) {
    const CliDir dir;
    const fs::path swc = dir.write("n.swc", "1 1 0 0 0 3 -1\n2 3 10 0 0 1 1\n3 3 10 8 0 1 2\n");
    const fs::path out = dir.path() / "o.vdb";
    auto stats = [&](const std::vector<std::string>& extra) {
        std::vector<std::string> args{swc.string(), swc.string(), "--voxel", "0.5um", "--dye", "AF488", "--concentration", "10uM", "--grid", "cells",
                                      "-o", out.string()};
        args.insert(args.end(), extra.begin(), extra.end());
        const CliRun r = dir.run(args);
        EXPECT_EQ(r.exitCode, 0) << r.err;
        return gridNamed(readVdbGridStats(out.string()), "cells");
    };
    const VdbGridStats overlapping = stats({});
    const VdbGridStats apart = stats({"--offset", "0um,0um,0um", "--offset", "50um,0um,0um"});
    const VdbGridStats turned = stats({"--offset", "0um,0um,0um", "--offset", "50um,0um,0um", "--rotate", "z:90,x:30"});
    EXPECT_FLOAT_EQ(static_cast<float>(overlapping.max), 20.0f);
    EXPECT_FLOAT_EQ(static_cast<float>(apart.max), 10.0f);
    EXPECT_EQ(apart.activeVoxels, 2 * (overlapping.activeVoxels));
    EXPECT_NEAR(turned.sum, apart.sum, 0.02 * apart.sum);  // the same dye, turned (voxel sampling differs)
    const CliRun bad = dir.run({swc.string(), "--voxel", "0.5um", "--dye", "AF488", "--concentration", "10uM", "--rotate", "w:90", "-o", out.string()});
    EXPECT_EQ(bad.exitCode, 2);
    EXPECT_TRUE(contains(bad.err, "--rotate") && contains(bad.err, "w:90")) << bad.err;
    const CliRun badOffset = dir.run({swc.string(), "--voxel", "0.5um", "--dye", "AF488", "--concentration", "10uM", "--offset", "1um,2um", "-o",
                                      out.string()});
    EXPECT_EQ(badOffset.exitCode, 2);
    EXPECT_TRUE(contains(badOffset.err, "--offset") && contains(badOffset.err, "1um,2um")) << badOffset.err;
}

TEST(VoxelizeCli, BadInputNamesTheValue) {
    const CliDir dir;
    const fs::path swc = dir.write("n.swc", "1 1 0 0 0 3 -1\n2 3 10 0 0 1 1\n");
    const std::string out = (dir.path() / "o.vdb").string();
    struct Case {
        std::vector<std::string> args;
        int code;
        std::vector<std::string> parts;
    };
    const std::string bad = dir.write("bad.swc", "1 1 0 0 0 3 -1\n2 3 10 0 0 1 7\n").string();
    const std::string missing = (dir.path() / "missing.swc").string();
    const Case cases[] = {
        {{swc.string(), "--voxel", "0.5um", "--dye", "AF489", "--concentration", "10uM", "-o", out}, 2, {"AF489", "did you mean"}},
        {{missing, "--voxel", "0.5um", "--dye", "AF488", "--concentration", "10uM", "-o", out}, 3, {missing}},
        {{bad, "--voxel", "0.5um", "--dye", "AF488", "--concentration", "10uM", "-o", out}, 2, {bad + ":2:", "parent", "7"}},
        {{swc.string(), "--voxel", "0um", "--dye", "AF488", "--concentration", "10uM", "-o", out}, 2, {"--voxel", "0um"}},
        {{swc.string(), "--voxel", "0", "--dye", "AF488", "--concentration", "10uM", "-o", out}, 2, {"--voxel", "\"0\""}},
        {{swc.string(), "--voxel", "0.5um", "--dye", "AF488", "--concentration=-1uM", "-o", out}, 2, {"--concentration", "-1uM"}},
        {{swc.string(), "--voxel", "0.5um", "--dye", "AF488", "--concentration", "10 g/L", "-o", out}, 2, {"--concentration", "10 g/L"}},
        {{swc.string(), "--voxel", "0.5um", "--dye", "AF488,AF594", "--concentration", "10uM", "-o", out}, 2, {"--dye", "one per SWC file"}},
        {{swc.string(), "--voxel", "0.5um", "--dye", "AF488", "--concentration", "10uM", "--mode", "hollow", "-o", out}, 2, {"hollow"}},
        {{swc.string(), "--voxel", "0.5um", "--dye", "AF488", "--concentration", "10uM", "-o", (dir.path() / "no/o.vdb").string()},
         3,
         {(dir.path() / "no").string()}},
        {{swc.string(), "--voxel", "0.5um", "--dye", "AF488", "--concentration", "10uM", "-o", (dir.path() / "o.exr").string()}, 2, {"o.exr"}},
    };
    for (const Case& c : cases) {
        const CliRun r = dir.run(c.args);
        std::string cmd;
        for (const auto& a : c.args) cmd += a + " ";
        EXPECT_EQ(r.exitCode, c.code) << cmd << "\n" << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << cmd << "\n" << r.err;
        EXPECT_EQ(r.err.rfind("fluorosim: ", 0), 0u) << r.err;
        for (const auto& p : c.parts) EXPECT_TRUE(contains(r.err, p)) << cmd << ": no \"" << p << "\" in " << r.err;
        EXPECT_FALSE(fs::exists(out)) << cmd;
    }
}

}  // namespace
}  // namespace fluorosim
