#pragma once
// Pixel blocks of 2^k × 2^k over an image, for light imaged far from focus: its defocus disc is many blocks
// wide, so block means interpolated bilinearly between block centres blur it by far less than the disc
// (docs/model.md, "Pooled imaging far from focus"). One rule for the camera paths and the traced emission.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

namespace fluorosim::optics {

// Blocks of 2^k × 2^k pixels over an image, the last ones cut by its edge, and the bilinear weights that
// spread block means back to every pixel: the pooling's one rule, for the total and for each label.
struct PoolingBlocks {
    int width, height, k, block, bx, by;
    PoolingBlocks(int w, int h, int level) : width(w), height(h), k(level), block(1 << level), bx(((w - 1) >> level) + 1), by(((h - 1) >> level) + 1) {}
    size_t count() const { return static_cast<size_t>(bx) * by; }
    size_t of(int x, int y) const { return static_cast<size_t>((y >> k) * bx + (x >> k)); }
    double pixels(size_t b) const {
        const int cx = static_cast<int>(b % static_cast<size_t>(bx)), cy = static_cast<int>(b / static_cast<size_t>(bx));
        return double(std::min(block, width - cx * block)) * std::min(block, height - cy * block);
    }
    // f(pixel, weights): the four (block, weight) pairs that interpolate between block centres at a pixel.
    template <class F>
    void forEachPixel(F&& f) const {
        auto axis = [&](int p, int blocks, int* c0, int* c1, double* t) {
            const double u = (p + 0.5) / block - 0.5;
            *c0 = std::clamp(static_cast<int>(std::floor(u)), 0, blocks - 1);
            *c1 = std::min(*c0 + 1, blocks - 1);
            *t = std::clamp(u - *c0, 0.0, 1.0);
        };
        for (int y = 0; y < height; ++y) {
            int y0, y1, x0, x1;
            double fy, fx;
            axis(y, by, &y0, &y1, &fy);
            for (int x = 0; x < width; ++x) {
                axis(x, bx, &x0, &x1, &fx);
                const std::array<std::pair<size_t, double>, 4> w{{{static_cast<size_t>(y0 * bx + x0), (1 - fx) * (1 - fy)},
                                                                  {static_cast<size_t>(y0 * bx + x1), fx * (1 - fy)},
                                                                  {static_cast<size_t>(y1 * bx + x0), (1 - fx) * fy},
                                                                  {static_cast<size_t>(y1 * bx + x1), fx * fy}}};
                f(static_cast<size_t>(y) * width + x, w);
            }
        }
    }
};

// An image of per-pixel means pooled over blocks of 2^k pixels (PoolingBlocks' rule, for one image).
std::vector<double> poolImage(const std::vector<double>& image, int width, int height, int k);

}  // namespace fluorosim::optics
