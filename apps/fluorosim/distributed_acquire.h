#pragma once
// `acquire` over the ranks of an MPI run (cluster/cluster.h): each (channel, plane) of the stack is
// one task of a farm, so planes go to whichever rank is free. The root collects every plane, stores it
// (dark current, camera read-out) and hands it to the callbacks, which checkpoint it; the other ranks
// only render. Planes are keyed by channel name and plane index (optics::planeStreamKey), so the stack
// is bit-identical to a single process's for any number of ranks.
#include "optics/acquisition.h"

namespace fluorosim::app {

// Root, or alone: the same contract as optics::acquireStack (which it is when alone), except that
// `callbacks.progress` advances by whole planes and planes finish in any order.
bool acquireStackOnCluster(const Scene& scene, const optics::Microscope& microscope, optics::Stack& stack,
                           const optics::AcquireOptions& options, const optics::StackCallbacks& callbacks);
// Other ranks: render the planes the root hands out until the stack is done.
void servePlanes(const Scene& scene, const optics::Microscope& microscope, const optics::AcquireOptions& options);

}  // namespace fluorosim::app
