#pragma once
// Regression images for the viewer's tests: a frame against a stored PNG with VTK's own measure
// (vtkImageDifference's thresholded error, the number vtkTesting::RegressionTest compares with its
// threshold, 0.15 by default).
#include <filesystem>

#include "viewer/viewer.h"

namespace fluorosim::viewer {

inline constexpr double kVtkRegressionThreshold = 0.15;

// Thresholded error of `frame` against the PNG `baseline`; infinity when the sizes differ. Throws
// IoError when the baseline cannot be read.
double imageDifference(const FrameImage& frame, const std::filesystem::path& baseline);
// Writes a frame as a PNG. Throws IoError.
void writePng(const FrameImage& frame, const std::filesystem::path& png);

}  // namespace fluorosim::viewer
