#pragma once
// Sums of 2-D linear convolutions, Σ_b image_b ⊛ kernel_b, and their adjoint (correlations), through
// FFTW (which only the .cpp includes).
// Images are width × height, row-major; kernels are (2R + 1)² row-major with the centre at (R, R).
// The transform is large enough that nothing wraps around. Kernels are transformed once; convolveSum
// may run on several threads at once.
#include <memory>
#include <vector>

namespace fluorosim::optics {

class FftConvolution {
public:
    FftConvolution(int width, int height, int kernelRadius);  // throws ConfigError for non-positive sizes
    ~FftConvolution();
    FftConvolution(FftConvolution&&) noexcept;
    FftConvolution& operator=(FftConvolution&&) noexcept;

    int addKernel(const std::vector<double>& kernel);  // returns its index; throws ConfigError for a wrong size
    int kernelCount() const;
    // Σ_b images[b] ⊛ kernel b; an empty image is skipped.
    std::vector<double> convolveSum(const std::vector<std::vector<double>>& images) const;
    // The adjoint of one term: out(u) = Σ_x image(x) kernel_b(x − u), over the same image size.
    std::vector<double> correlate(const std::vector<double>& image, int kernel) const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace fluorosim::optics
