#pragma once
// The field-lit dye of a plane, as the traced photons' sources (optics/scattered_emission.h).
// The dye in the excitation field's box, in media whose every dye lies in grids: the index cells of the
// grids (between voxel centres, where trilinear look-ups interpolate one set of eight voxels) whose corners
// hold dye, drawn in proportion to their largest corner's concentration times the light at their centre (the
// beams' unattenuated light and the field's, plus the mean of that over the cells, so that every cell that
// holds dye can be drawn), then a point uniform in the cell. The cells are disjoint: a point's density is its
// cell's. Its weight, the emission there over that density, is bounded: the concentration at the point is at
// most the largest corner's, and the light varies little over a cell.
//
// Built once per channel and field: the traces of one plane (a pilot, the rest, more) share it.
#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "optics/imaging.h"
#include "render/fluence_field.h"
#include "render/path_tracer.h"
#include "scene/scene.h"

namespace fluorosim::optics {

class DyeCells {
public:
    // `lines`: the beams' line wavelengths whose light the cells weigh; `detection`: the channel's
    // photoelectrons per joule at λ, weighing each dye by what the channel sees of its emission.
    DyeCells(const Scene& scene, const PathTracer& tracer, const BeamExcitationField& field, const std::vector<double>& lines,
             const std::function<double(double)>& detection, const Imaging& imaging, int threads);
    bool empty() const { return cells_.empty(); }
    const std::vector<bool>& media() const { return media_; }  // by index: media whose dye the cells hold
    struct Sample {
        Vec3 p;
        int medium = kNone;
        double pdf = 0;  // per mm³
    };
    Sample sample(double uCell, double ux, double uy, double uz) const;

private:
    struct Cell {
        int medium;
        int64_t v[3];  // the cell [v, v + 1) in index space
        double weight, volumeMm3;
    };
    const Scene& scene_;
    std::vector<Cell> cells_;
    std::vector<double> cdf_;
    double total_ = 0;
    std::vector<bool> media_;
};

}  // namespace fluorosim::optics
