#pragma once
// ITK images <-> plain images. For ITK translation units only (see plain_image.h).
#include <itkImage.h>

#include "organfit/itkbridge/plain_image.h"

namespace organfit::itkbridge {

using FloatImage = itk::Image<float, 3>;
using MaskImage = itk::Image<unsigned char, 3>;

FloatImage::Pointer to_itk(const PlainFloatImage& image);
PlainMask to_plain(const MaskImage* image);

}  // namespace organfit::itkbridge
