#include "viewer/image_compare.h"

#include <vtkImageData.h>
#include <vtkImageDifference.h>
#include <vtkNew.h>
#include <vtkPNGReader.h>
#include <vtkPNGWriter.h>

#include <algorithm>
#include <limits>

#include "viewer/viewer_impl.h"

namespace fluorosim::viewer {

double imageDifference(const FrameImage& frame, const std::filesystem::path& baseline) {
    vtkNew<vtkPNGReader> reader;
    if (!std::filesystem::exists(baseline) || !reader->CanReadFile(baseline.string().c_str()))
        throw IoError(baseline.string() + ": cannot read the baseline image");
    reader->SetFileName(baseline.string().c_str());
    reader->Update();
    int dims[3];
    reader->GetOutput()->GetDimensions(dims);
    if (dims[0] != frame.width || dims[1] != frame.height) return std::numeric_limits<double>::infinity();
    vtkNew<vtkImageData> image;
    setImageRgb(image, {frame.width, frame.height, 1}, Vec3(), {1, 1, 1}, frame.rgb);
    vtkNew<vtkImageDifference> difference;
    difference->SetInputData(image);
    difference->SetImageConnection(reader->GetOutputPort());
    difference->Update();
    return difference->GetThresholdedError();
}

void writePng(const FrameImage& frame, const std::filesystem::path& png) {
    vtkNew<vtkImageData> image;
    setImageRgb(image, {frame.width, frame.height, 1}, Vec3(), {1, 1, 1}, frame.rgb);
    vtkNew<vtkPNGWriter> writer;
    writer->SetFileName(png.string().c_str());
    writer->SetInputData(image);
    writer->Write();
    if (writer->GetErrorCode() || !std::filesystem::exists(png)) throw IoError(png.string() + ": cannot write the PNG");
}

}  // namespace fluorosim::viewer
