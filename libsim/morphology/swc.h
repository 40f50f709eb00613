#pragma once
// Neuron morphologies in the SWC format of NeuroMorpho.Org (one sample per line:
// id type x y z radius parent, lengths in µm) and the surface model built from them: a sphere for
// the soma and round cones (convex hulls of two end spheres) between samples. The analytic volume
// and the voxelizer (volume/voxelize.h) use the same pieces, so they agree by construction.
#include <string>
#include <utility>
#include <string_view>
#include <vector>

#include "core/vec3.h"

namespace fluorosim {

struct SwcSample {
    int id = 0;
    int type = 0;  // 1 soma, 2 axon, 3 basal dendrite, 4 apical dendrite, others allowed
    Vec3 positionUm;
    double radiusUm = 0;
    int parent = -1;  // -1 for a root
    int line = 0;     // line in the source file, for messages
};

struct Morphology {
    std::string source;  // file name, for messages
    std::vector<SwcSample> samples;  // in file order
};

constexpr int kSwcSomaType = 1;

// Reads an SWC file. Throws IoError when it cannot be opened or read, ConfigError "FILE:LINE: ..."
// naming the field and value for a malformed line, a non-finite number, a non-positive radius, a
// duplicate id, an unknown parent, a cycle, or a file without samples.
Morphology readSwc(const std::string& path);
// The same on text already in memory; `source` names it in messages.
Morphology parseSwc(std::string_view text, const std::string& source);

// A rigid placement: rotations about axes x, y or z (degrees, right-handed, applied in order) about the
// morphology's first root sample (its soma), then a translation (µm). Radii are kept.
struct Placement {
    std::vector<std::pair<char, double>> rotationsDeg;  // ('z', 90), ('x', 15), ...
    Vec3 offsetUm;
    bool identity() const { return rotationsDeg.empty() && offsetUm.x == 0 && offsetUm.y == 0 && offsetUm.z == 0; }
};
void place(Morphology& m, const Placement& p);

// One piece of the surface model, in µm: a sphere (sphere = true, centre a, radius ra) or the
// round cone spanned by the spheres (a, ra) and (b, rb).
struct MorphologyPiece {
    Vec3 aUm, bUm;
    double raUm = 0, rbUm = 0;
    bool sphere = false;
};

// The pieces of a morphology:
//  - soma: a NeuroMorpho 3-point soma (three type-1 samples, the 2nd and 3rd children of the 1st at
//    ±r along y) is one sphere of radius r at the 1st sample; a type-1 sample with no type-1
//    parent or child is a sphere; other type-1 samples give round cones to their type-1 parent;
//  - a sample whose parent is a soma sample gives a cylinder with its own radius from the point of
//    the parent's soma sphere facing it (not from the soma centre, which would make a wide cone);
//    nothing if it lies inside that sphere;
//  - every other sample gives a round cone to its parent; roots give nothing by themselves.
std::vector<MorphologyPiece> morphologyPieces(const Morphology& m);

// Spheres' volumes plus the frusta πL/3 (ra² + ra·rb + rb²) of the round cones, in µm³. Overlaps at
// joints and branch points are counted twice and the end caps of the round cones not at all, so
// the voxelized union differs from it by O(r/L) at joints and tips.
double analyticVolumeUm3(const Morphology& m);

// Median radius of the non-soma samples (of all samples if there are none), in µm.
double medianRadiusUm(const Morphology& m);

}  // namespace fluorosim
