// The organfit side of the bridge: Eigen-based types <-> plain images. No ITK here.
#include "organfit/itkbridge/itk_images.h"

namespace organfit::itkbridge {

PlainGeometry to_plain(const geometry::ImageGeometry& g) {
  PlainGeometry p;
  p.size = g.size;
  for (int d = 0; d < 3; ++d) {
    p.spacing_mm[d] = g.spacing_mm[d];
    p.origin_mm[d] = g.origin_mm[d];
    for (int e = 0; e < 3; ++e)
      p.direction[3 * d + e] = g.direction(d, e);
  }
  return p;
}

geometry::ImageGeometry from_plain(const PlainGeometry& p) {
  geometry::ImageGeometry g;
  g.size = p.size;
  for (int d = 0; d < 3; ++d) {
    g.spacing_mm[d] = p.spacing_mm[d];
    g.origin_mm[d] = p.origin_mm[d];
    for (int e = 0; e < 3; ++e)
      g.direction(d, e) = p.direction[3 * d + e];
  }
  return g;
}

PlainMask to_plain(const geometry::LabelVolume& labels) {
  return {to_plain(labels.geometry), labels.labels};
}

geometry::LabelVolume from_plain(const PlainMask& mask) {
  geometry::LabelVolume out(from_plain(mask.geometry));
  out.labels = mask.labels;
  return out;
}

void write_label_volume(const std::filesystem::path& file, const geometry::LabelVolume& labels) {
  write_mask(file, to_plain(labels));
}

geometry::LabelVolume read_label_volume(const std::filesystem::path& file) {
  return from_plain(read_mask(file));
}

void write_float_volume(const std::filesystem::path& file, const geometry::ImageGeometry& g,
                        const std::vector<float>& values) {
  write_float_image(file, {to_plain(g), values});
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
