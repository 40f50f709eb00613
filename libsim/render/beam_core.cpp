#include "render/beam_core.h"

namespace fluorosim {

std::vector<BeamLine> beamLines(const std::vector<Light>& lights) {
    std::vector<BeamLine> lines;
    for (const Light& light : lights)
        if (const BeamLight* b = std::get_if<BeamLight>(&light))
            for (const SpectralLine& line : b->profile->spectrum().spectralLines())
                if (line.power > 0) lines.push_back({b->profile.get(), line.lambdaNm, line.power});
    return lines;
}

}  // namespace fluorosim
