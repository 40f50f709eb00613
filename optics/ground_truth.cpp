#include "optics/ground_truth.h"

#include <map>

#include "core/parallel.h"
#include "optics/imaging_operator.h"
#include "render/straight_line.h"

namespace fluorosim::optics {

Vec3 pixelCentreMm(const Microscope& m, int plane, double x, double y) {
    const double pixel = m.pixelSizeMm();
    return m.focalPlaneAt(m.planeOffsetMm(plane)).centreMm + m.focus.right() * ((x + 0.5 - 0.5 * m.width) * pixel) +
           m.focus.imageUp() * ((0.5 * m.height - (y + 0.5)) * pixel);
}

GroundTruth groundTruth(const Scene& scene, const Microscope& m, const std::vector<size_t>& channels, const AcquireOptions& options) {
    GroundTruth out;
    out.width = m.width;
    out.height = m.height;
    out.planes = m.stack.planes;
    out.channels = channels;
    const size_t planePixels = static_cast<size_t>(m.width) * static_cast<size_t>(m.height);
    const size_t stackPixels = planePixels * static_cast<size_t>(m.stack.planes);

    // Each dye once, by id; where several media hold it, the medium at the point gives its value.
    std::map<std::string, size_t> dyeIndex;
    for (const Medium& med : scene.media)
        for (const DyeComponent& d : med.dyes())
            if (dyeIndex.emplace(d.dye.id(), out.dyes.size()).second) out.dyes.push_back(d.dye.id());
    out.concentration.assign(out.dyes.size() * stackPixels, 0.0f);
    const Vec3 axis = m.focus.axis();
    const size_t rows = static_cast<size_t>(m.stack.planes) * static_cast<size_t>(m.height);
    parallelFor(rows, options.threads, [&](size_t row) {
        const int plane = static_cast<int>(row / static_cast<size_t>(m.height)), y = static_cast<int>(row % static_cast<size_t>(m.height));
        ChannelValues values{};
        for (int x = 0; x < m.width; ++x) {
            const Vec3 p = pixelCentreMm(m, plane, x, y);
            const int medium = mediumAt(scene, p, axis);
            if (medium == kNone) continue;
            const Medium& med = scene.media[static_cast<size_t>(medium)];
            if (med.dyes().empty()) continue;
            med.channelValues(p, values.data());
            for (size_t i = 0; i < med.dyes().size(); ++i) {
                const size_t d = dyeIndex.at(med.dyes()[i].dye.id());
                out.concentration[d * stackPixels + row * static_cast<size_t>(m.width) + static_cast<size_t>(x)] =
                    static_cast<float>(values[static_cast<size_t>(kFirstDyeChannel) + i]);
            }
        }
    });

    AcquireOptions ideal = options;
    ideal.unscattered.attenuation = false;
    ideal.field.photons = 0;  // nor the tissue's scattered excitation
    StackOperator op(scene, m, channels, ideal);
    op.refreshGains(scene, options.cancel);
    const ParameterMap map = ParameterMap::labels(op.labels(), false);
    const std::vector<double> image = op.apply(map, std::vector<double>(map.size(), 1.0), true);
    out.ideal.assign(image.begin(), image.end());
    return out;
}

}  // namespace fluorosim::optics
