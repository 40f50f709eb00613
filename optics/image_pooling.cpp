#include "optics/image_pooling.h"

namespace fluorosim::optics {

std::vector<double> poolImage(const std::vector<double>& image, int width, int height, int k) {
    const PoolingBlocks blocks(width, height, k);
    std::vector<double> mean(blocks.count(), 0.0);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) mean[blocks.of(x, y)] += image[static_cast<size_t>(y) * width + x];
    for (size_t b = 0; b < mean.size(); ++b) mean[b] /= blocks.pixels(b);
    std::vector<double> out(image.size(), 0.0);
    blocks.forEachPixel([&](size_t pixel, const std::array<std::pair<size_t, double>, 4>& w) {
        for (const auto& [i, wi] : w) out[pixel] += wi * mean[i];
    });
    return out;
}

}  // namespace fluorosim::optics
