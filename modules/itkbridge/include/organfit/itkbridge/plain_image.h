#pragma once
// Plain images for the ITK side of the bridge: no Eigen here.
//
// Why: ITK 5.2 bundles its own Eigen (3.3) and organfit uses the system's (3.4); both
// use the same include guards, so a translation unit must never see both. ITK code in
// organfit includes only this header; itk_images.h converts on the Eigen side.
#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "organfit/geometry/plain_image.h"

namespace organfit::itkbridge {

using geometry::PlainGeometry;
using geometry::PlainMask;

struct PlainFloatImage {
  PlainGeometry geometry;
  std::vector<float> values;  ///< i fastest
};

/// Why `file` cannot be written as an image, or empty when it can: its name must end in
/// one of the writers' formats, .nrrd, .nhdr, .mha, .mhd, .nii or .nii.gz.
std::string image_file_name_problem(const std::filesystem::path& file);

/// Writes a mask; the format follows the extension (.nrrd, .nhdr, .mha, .mhd, .nii,
/// .nii.gz). Written under a temporary name and renamed: whole or not at all. Throws
/// InputError naming the file on an unknown extension or a failed write.
void write_mask(const std::filesystem::path& file, const PlainMask& mask);
/// A scalar float image (e.g. a Jacobian determinant), written as write_mask writes but
/// uncompressed.
void write_float_image(const std::filesystem::path& file, const PlainFloatImage& image);
/// The same from a geometry and its values (one per voxel, i fastest), not copied.
void write_float_image(const std::filesystem::path& file, const PlainGeometry& geometry,
                       const std::vector<float>& values);
/// A field of 3-vectors (x, y, z per voxel, i fastest; mm in the image's physical frame),
/// written as an ITK vector image of float (.mha, .nrrd, .nii): the form plastimatch
/// reads as a vector field (`--xf`). Written as write_mask writes but uncompressed.
void write_vector_image(const std::filesystem::path& file, const PlainGeometry& geometry,
                        const std::vector<float>& xyz);
/// A field of 3-vectors read back (any file ITK reads as a 3-component float vector image):
/// its geometry and x, y, z per voxel, i fastest. Throws InputError naming the file when it
/// is missing, unreadable or not 3 components.
PlainGeometry read_vector_image(const std::filesystem::path& file, std::vector<float>& xyz);
/// Reads a mask (any image ITK reads, cast to 8 bits). Throws InputError naming the file.
PlainMask read_mask(const std::filesystem::path& file);
/// Reads any scalar image ITK reads as float values (e.g. an ultrasound volume). Throws
/// InputError naming the file.
PlainFloatImage read_float_image(const std::filesystem::path& file);

}  // namespace organfit::itkbridge
