#pragma once
// `render` over the ranks of an MPI run (cluster/cluster.h): the image is cut into bands of rows, each
// band one task of a farm, rendered at the full sample count into a film of its own and sent to the root
// as the film's sums, which the root places into the whole film. Samples are keyed by absolute pixel and
// sample index, so the image is bit-identical to a single process's for any number of ranks.
//
// Under MPI a band is the unit of work, so there are no partial passes: an interrupted distributed render
// (a signal, or a rank that dies) writes no image.
#include "render/renderer.h"

namespace fluorosim::app {

// Root, or alone: render() (which it is when alone) with the image distributed; `options.passFinished`
// is not called under MPI and `options.progress` advances by whole bands.
RenderSummary renderOnCluster(const Scene& scene, Film& film, const RenderOptions& options);
// Other ranks: render the bands the root hands out, into films shaped like `film`'s rows.
void serveBands(const Scene& scene, const Film& film, const RenderOptions& options);

}  // namespace fluorosim::app
