// The organfit side of the bridge: Eigen-based types <-> plain images. No ITK here.
#include "organfit/itkbridge/itk_images.h"

namespace organfit::itkbridge {

void write_label_volume(const std::filesystem::path& file, const geometry::LabelVolume& labels) {
  write_mask(file, to_plain(labels));
}

geometry::LabelVolume read_label_volume(const std::filesystem::path& file) {
  return from_plain(read_mask(file));
}

void write_float_volume(const std::filesystem::path& file, const geometry::ImageGeometry& g,
                        const std::vector<float>& values) {
  write_float_image(file, to_plain(g), values);
}

void write_vector_volume(const std::filesystem::path& file, const geometry::ImageGeometry& g,
                         const std::vector<float>& xyz) {
  write_vector_image(file, to_plain(g), xyz);
}

VectorVolume read_vector_volume(const std::filesystem::path& file) {
  VectorVolume v;
  v.geometry = from_plain(read_vector_image(file, v.xyz));
  return v;
}

ScalarImage read_scalar_image(const std::filesystem::path& file) {
  PlainFloatImage plain = read_float_image(file);
  return {from_plain(plain.geometry), std::move(plain.values)};
}

}  // namespace organfit::itkbridge
