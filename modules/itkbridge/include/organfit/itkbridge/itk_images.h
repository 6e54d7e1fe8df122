#pragma once
// organfit's plain images <-> the bridge's plain (Eigen-free) images, and files.
// Include this on the organfit side; ITK code includes plain_image.h only.
#include <filesystem>
#include <vector>

#include "organfit/geometry/image_geometry.h"
#include "organfit/itkbridge/plain_image.h"

namespace organfit::itkbridge {

using geometry::from_plain;  // ImageGeometry and LabelVolume <-> plain arrays
using geometry::to_plain;

/// write_mask / read_mask for a LabelVolume (geometry kept exactly).
void write_label_volume(const std::filesystem::path& file, const geometry::LabelVolume& labels);
geometry::LabelVolume read_label_volume(const std::filesystem::path& file);

/// A scalar float image on a geometry (write_float_image).
void write_float_volume(const std::filesystem::path& file, const geometry::ImageGeometry& g,
                        const std::vector<float>& values);
/// A vector field on a geometry, x y z per voxel in mm (write_vector_image).
void write_vector_volume(const std::filesystem::path& file, const geometry::ImageGeometry& g,
                         const std::vector<float>& xyz);

/// A vector field read back (read_vector_image): x y z per voxel in mm.
struct VectorVolume {
  geometry::ImageGeometry geometry;
  std::vector<float> xyz;  ///< i fastest
};
VectorVolume read_vector_volume(const std::filesystem::path& file);

/// A scalar image as float values with its geometry (any pixel type ITK reads).
struct ScalarImage {
  geometry::ImageGeometry geometry;
  std::vector<float> values;  ///< i fastest
};
ScalarImage read_scalar_image(const std::filesystem::path& file);

}  // namespace organfit::itkbridge
