// ITK translation unit: plain images only (no Eigen-based organfit header).
#include "organfit/segmentation/seeded_region.h"

#include <itkBinaryBallStructuringElement.h>
#include <itkBinaryFillholeImageFilter.h>
#include <itkBinaryMorphologicalOpeningImageFilter.h>
#include <itkBinaryThresholdImageFilter.h>
#include <itkCommand.h>
#include <itkConnectedComponentImageFilter.h>
#include <itkConnectedThresholdImageFilter.h>
#include <itkCurvatureFlowImageFilter.h>
#include <itkRelabelComponentImageFilter.h>

#include <new>
#include <string>

#include "organfit/itkbridge/itk_conversions.h"
#include "organfit/support/error.h"
#include "organfit/support/progress.h"

namespace organfit::segmentation {

// ITK says it ran out of memory in its own exception: the run's out of memory (exit 2).
itkbridge::PlainMask seeded_region(const itkbridge::PlainFloatImage& hu,
                                   const PlainSeedOptions& o) try {
  using itkbridge::FloatImage;
  using itkbridge::MaskImage;
  auto fmt3 = [](const std::array<double, 3>& p) {
    char b[96];
    std::snprintf(b, sizeof b, "(%.1f, %.1f, %.1f) mm", p[0], p[1], p[2]);
    return std::string(b);
  };
  if (!(o.hu_low < o.hu_high))
    throw InputError("segment: the HU window is empty (low must be below high)");
  const FloatImage::Pointer image = itkbridge::to_itk(hu);
  FloatImage::PointType point;
  for (int d = 0; d < 3; ++d)
    point[d] = o.seed_mm[d];
  FloatImage::IndexType seed;
  if (!image->TransformPhysicalPointToIndex(point, seed))
    throw InputError("segment: the seed " + fmt3(o.seed_mm) + " is outside the CT");

  // Progress over the filters in their order; the smoothing takes most of the time (9.5 s
  // over a 260 mm search box on 0.5 mm slices).
  constexpr int kFilters = 7;
  Progress progress("segment", 100 * kFilters);
  auto follow = [&progress](itk::ProcessObject* filter, int place, const char* what) {
    filter->AddObserver(
        itk::ProgressEvent(), [&progress, filter, place, what](const itk::EventObject&) {
          progress.update(static_cast<long long>(100 * (place + filter->GetProgress())), what);
        });
  };
  auto smooth = itk::CurvatureFlowImageFilter<FloatImage, FloatImage>::New();
  follow(smooth, 0, "smoothing");
  smooth->SetInput(image);
  smooth->SetNumberOfIterations(o.smoothing_iterations);
  smooth->SetTimeStep(0.0625);
  smooth->Update();
  const float at_seed = smooth->GetOutput()->GetPixel(seed);
  if (at_seed < o.hu_low || at_seed > o.hu_high) {
    char b[160];
    std::snprintf(
        b, sizeof b,
        "segment: the (smoothed) CT reads %.0f HU at the seed %s, outside the window [%.0f, %.0f]",
        at_seed, fmt3(o.seed_mm).c_str(), o.hu_low, o.hu_high);
    throw InputError(b);
  }
  auto grow = itk::ConnectedThresholdImageFilter<FloatImage, MaskImage>::New();
  grow->SetInput(smooth->GetOutput());
  grow->SetLower(static_cast<float>(o.hu_low));
  grow->SetUpper(static_cast<float>(o.hu_high));
  grow->SetReplaceValue(1);
  grow->AddSeed(seed);

  using Ball = itk::BinaryBallStructuringElement<unsigned char, 3>;
  Ball ball;
  ball.SetRadius(static_cast<unsigned long>(o.opening_radius_voxels));
  ball.CreateStructuringElement();
  auto open = itk::BinaryMorphologicalOpeningImageFilter<MaskImage, MaskImage, Ball>::New();
  open->SetInput(grow->GetOutput());
  open->SetKernel(ball);
  open->SetForegroundValue(1);

  using Labels = itk::Image<unsigned int, 3>;
  auto components = itk::ConnectedComponentImageFilter<MaskImage, Labels>::New();
  components->SetInput(open->GetOutput());
  auto relabel = itk::RelabelComponentImageFilter<Labels, Labels>::New();  // 1 = largest
  relabel->SetInput(components->GetOutput());
  auto largest = itk::BinaryThresholdImageFilter<Labels, MaskImage>::New();
  largest->SetInput(relabel->GetOutput());
  largest->SetLowerThreshold(1);
  largest->SetUpperThreshold(1);
  largest->SetInsideValue(1);
  largest->SetOutsideValue(0);
  auto fill = itk::BinaryFillholeImageFilter<MaskImage>::New();
  fill->SetInput(largest->GetOutput());
  fill->SetForegroundValue(1);
  follow(grow, 1, "growing from the seed");
  follow(open, 2, "opening");
  follow(components, 3, "its pieces");
  follow(relabel, 4, "its pieces");
  follow(largest, 5, "the largest piece");
  follow(fill, 6, "filling its holes");
  fill->Update();
  progress.finish();
  return itkbridge::to_plain(fill->GetOutput());
} catch (const itk::MemoryAllocationError&) {
  throw std::bad_alloc();
}

}  // namespace organfit::segmentation
