// Film: spectral binning of samples, and the rows render() stages a pass in.
#include <gtest/gtest.h>

#include <sstream>

#include "render/film.h"
#include "support/test_scenes.h"

namespace fluorosim {
namespace {

using testing::flatCmf;

// Found in review: a line exactly at the range maximum fell outside the last bin.
TEST(Film, LineAtRangeMaximumLandsInLastBin) {
    Film film(1, 1, 400, 700, 50, flatCmf());
    film.addSample(0, 0, PathRadiance{SampledSpectrum(2.0), SampledSpectrum(0.0)}, SampledWavelengths::atLine(700.0, 1.0));
    const ExrImage img = film.image(1);
    const auto& v = img.spectral[0].values;
    EXPECT_NEAR(v.back() * 50.0, 2.0, 2e-7);  // per nm times the bin width = the line's value (stored as float)
}

std::string state(const Film& f) {
    std::ostringstream os;
    f.writeState(os);
    return os.str();
}

TEST(Film, StagedRowsGiveTheSameSumsAsDirectSamples) {
    Film direct(3, 2, 400, 700, 30, flatCmf(), true), staged(3, 2, 400, 700, 30, flatCmf(), true);
    auto sample = [](int k) {
        const SampledWavelengths wl = SampledWavelengths::sampleUniform(0.137 * k - static_cast<int>(0.137 * k), 400, 700);
        return std::pair{PathRadiance{SampledSpectrum(0.1 * k + 0.01), SampledSpectrum(0.03 * k)}, wl};
    };
    int k = 0;
    for (int pass = 0; pass < 3; ++pass)
        for (int y = 0; y < 2; ++y) {
            Film::Row row;
            row.reset(y);
            for (int x = 0; x < 3; ++x, ++k) {
                const auto [L, wl] = sample(k);
                direct.addSample(x, y, L, wl);
                staged.addSample(row, x, L, wl);
            }
            // Until committed, the film keeps its previous sums.
            EXPECT_NE(state(direct), state(staged));
            staged.commit(row);
        }
    EXPECT_EQ(state(direct), state(staged));
    // A non-finite sample is counted in the row and dropped.
    Film::Row row;
    row.reset(1);
    staged.addSample(row, 2, PathRadiance{SampledSpectrum(NAN), SampledSpectrum(0.0)}, sample(1).second);
    staged.commit(row);
    EXPECT_EQ(staged.nonFiniteSamples(), 1u);
}

}  // namespace
}  // namespace fluorosim
