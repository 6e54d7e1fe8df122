#pragma once
// DICOM ultrasound images (single- or multi-frame) as grey frames with their pixel size.
//
// Colour is converted to grey (RGB and YBR by luminance 0.299 R + 0.587 G + 0.114 B;
// PALETTE COLOR through its lookup table first). The physical pixel size comes from the
// Sequence of Ultrasound Regions: the first region whose physical units are cm (3) along
// both axes gives Physical Delta X/Y (cm) and its bounds. A file without such a region
// is refused unless a pixel size is given: its pixels have no trustworthy size.
#include <array>
#include <filesystem>
#include <string>
#include <vector>

namespace organfit::dicom {

struct UsImage {
  int width = 0, height = 0, frames = 0;
  double pixel_mm_x = 0, pixel_mm_y = 0;
  bool calibrated = false;                ///< the size came from an ultrasound region
  std::array<int, 4> region{0, 0, 0, 0};  ///< x0, y0, x1, y1 of that region (pixels)
  std::string photometric;                ///< as stored (RGB, PALETTE COLOR, MONOCHROME2, ...)
  std::vector<float> grey;                ///< width x height x frames, row-major per frame
};

/// Reads `file`. `pixel_mm` > 0 overrides (or supplies) the pixel size. Throws
/// InputError "FILE: reason" on unreadable files, unsupported pixel data, or no calibrated
/// region and no pixel size given.
UsImage read_us_image(const std::filesystem::path& file, double pixel_mm = 0);

}  // namespace organfit::dicom
