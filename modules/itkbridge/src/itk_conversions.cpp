// The ITK side of the bridge: no Eigen-based organfit header may be included here.
#include "organfit/itkbridge/itk_conversions.h"

#include <itkImage.h>
#include <itkImageFileReader.h>
#include <itkImageFileWriter.h>
#include <itkImageIOFactory.h>
#include <itkMetaImageIOFactory.h>
#include <itkNiftiImageIOFactory.h>
#include <itkNrrdImageIOFactory.h>
#include <itkVector.h>

#include <algorithm>
#include <cstring>
#include <iostream>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::itkbridge {
namespace {

/// An image of geometry `g` with no pixels yet.
template <class Image>
typename Image::Pointer shaped(const PlainGeometry& g) {
  auto image = Image::New();
  typename Image::RegionType region;
  typename Image::SizeType size;
  typename Image::SpacingType spacing;
  typename Image::PointType origin;
  typename Image::DirectionType direction;
  for (unsigned d = 0; d < 3; ++d) {
    size[d] = static_cast<itk::SizeValueType>(g.size[d]);
    spacing[d] = g.spacing_mm[d];
    origin[d] = g.origin_mm[d];
    for (unsigned e = 0; e < 3; ++e)
      direction(d, e) = g.direction[3 * d + e];
  }
  region.SetSize(size);
  image->SetRegions(region);
  image->SetSpacing(spacing);
  image->SetOrigin(origin);
  image->SetDirection(direction);
  return image;
}

template <class Image>
typename Image::Pointer allocate(const PlainGeometry& g) {
  auto image = shaped<Image>(g);
  image->Allocate();
  return image;
}

/// An image of geometry `g` over `pixels` (g.voxel_count() of them), not copied: for a
/// writer, which only reads them (a field on a CT's grid is hundreds of MB; its copy was
/// the export's high-water mark). It must not outlive them.
template <class Image>
typename Image::Pointer over(const PlainGeometry& g, const typename Image::PixelType* pixels) {
  auto image = shaped<Image>(g);
  image->GetPixelContainer()->SetImportPointer(const_cast<typename Image::PixelType*>(pixels),
                                               static_cast<itk::SizeValueType>(g.voxel_count()),
                                               false);
  return image;
}

template <class Image>
PlainGeometry geometry_of(const Image* image) {
  PlainGeometry g;
  const auto size = image->GetLargestPossibleRegion().GetSize();
  for (unsigned d = 0; d < 3; ++d) {
    g.size[d] = static_cast<int>(size[d]);
    g.spacing_mm[d] = image->GetSpacing()[d];
    g.origin_mm[d] = image->GetOrigin()[d];
    for (unsigned e = 0; e < 3; ++e)
      g.direction[3 * d + e] = image->GetDirection()(d, e);
  }
  return g;
}

/// The file formats organfit reads and writes, registered once (explicitly: no
/// UseITK.cmake, see the CMakeLists).
void register_formats() {
  static std::once_flag once;
  std::call_once(once, [] {
    itk::NrrdImageIOFactory::RegisterOneFactory();
    itk::MetaImageIOFactory::RegisterOneFactory();
    itk::NiftiImageIOFactory::RegisterOneFactory();
  });
}

bool ends_with(const std::string& s, const char* ext) {
  const size_t n = std::strlen(ext);
  return s.size() > n && s.compare(s.size() - n, n, ext) == 0;
}

}  // namespace

FloatImage::Pointer to_itk(const PlainFloatImage& image) {
  auto out = allocate<FloatImage>(image.geometry);
  std::copy(image.values.begin(), image.values.end(), out->GetBufferPointer());
  return out;
}

PlainMask to_plain(const MaskImage* image) {
  PlainMask out;
  out.geometry = geometry_of(image);
  const unsigned char* p = image->GetBufferPointer();
  out.labels.assign(p, p + out.geometry.voxel_count());
  return out;
}

std::string image_file_name_problem(const fs::path& file) {
  const std::string name = file.filename().string();
  const char* known[] = {".nrrd", ".nhdr", ".mha", ".mhd", ".nii", ".nii.gz"};
  if (std::any_of(std::begin(known), std::end(known),
                  [&](const char* e) { return ends_with(name, e); }))
    return "";
  return "unknown image format (use .nrrd, .nhdr, .mha, .mhd, .nii or .nii.gz)";
}

namespace {
/// Writes an ITK image under a temporary name, renamed when whole.
/// `compress`: zlib, as ITK writes it (small and quick for masks; for float fields of tens
/// of MB it costs seconds and gains little: their mantissas are noise to zlib).
template <class Image>
void write_image(const fs::path& file, const Image* image, bool compress) {
  if (const std::string why = image_file_name_problem(file); !why.empty())
    throw InputError(file.string() + ": " + why);
  register_formats();
  TempPath temp(file);
  auto writer = itk::ImageFileWriter<Image>::New();
  writer->SetFileName(temp.path().string());
  writer->SetInput(image);
  writer->SetUseCompression(compress);
  // ITK's MetaImage writer reports a failed write on std::cerr and carries on: the failure
  // is found by the room it left (TempPath::commit) and reported in one line, so its text
  // is kept off the user's stderr while ITK writes (on this thread; no other writes there).
  std::ostringstream library_messages;
  struct Restore {
    std::streambuf* cerr;
    ~Restore() { std::cerr.rdbuf(cerr); }
  } restore{std::cerr.rdbuf(library_messages.rdbuf())};
  try {
    writer->Update();
  } catch (const itk::ExceptionObject& e) {
    check_room_left(temp.path().parent_path(), file);
    throw InputError(file.string() + ": cannot write the image");
  }
  temp.commit();
}
}  // namespace

void write_mask(const fs::path& file, const PlainMask& mask) {
  if (mask.labels.size() != mask.geometry.voxel_count())
    throw std::invalid_argument("write_mask: one label per voxel needed");
  write_image(file, over<MaskImage>(mask.geometry, mask.labels.data()).GetPointer(), true);
}

void write_float_image(const fs::path& file, const PlainFloatImage& image) {
  write_float_image(file, image.geometry, image.values);
}

void write_float_image(const fs::path& file, const PlainGeometry& geometry,
                       const std::vector<float>& values) {
  if (values.size() != geometry.voxel_count())
    throw std::invalid_argument("write_float_image: one value per voxel needed");
  write_image(file, over<FloatImage>(geometry, values.data()).GetPointer(), false);
}

void write_vector_image(const fs::path& file, const PlainGeometry& geometry,
                        const std::vector<float>& xyz) {
  using VectorImage = itk::Image<itk::Vector<float, 3>, 3>;
  if (xyz.size() != 3 * geometry.voxel_count())
    throw std::invalid_argument("write_vector_image: 3 values per voxel needed");
  static_assert(sizeof(VectorImage::PixelType) == 3 * sizeof(float));
  write_image(
      file,
      over<VectorImage>(geometry, reinterpret_cast<const VectorImage::PixelType*>(xyz.data()))
          .GetPointer(),
      false);
}

PlainGeometry read_vector_image(const fs::path& file, std::vector<float>& xyz) {
  using VectorImage = itk::Image<itk::Vector<float, 3>, 3>;
  register_formats();
  std::error_code ec;
  if (!fs::exists(file, ec)) throw InputError(file.string() + ": no such file");
  auto io = itk::ImageIOFactory::CreateImageIO(file.string().c_str(),
                                               itk::ImageIOFactory::IOFileModeEnum::ReadMode);
  if (!io) throw InputError(file.string() + ": not an image format ITK reads");
  io->SetFileName(file.string());
  try {
    io->ReadImageInformation();
  } catch (const itk::ExceptionObject&) {
    throw InputError(file.string() + ": cannot read as an image");
  }
  if (io->GetNumberOfComponents() != 3 || io->GetNumberOfDimensions() != 3)
    throw InputError(file.string() + ": a 3D field of 3-component vectors expected");
  auto reader = itk::ImageFileReader<VectorImage>::New();
  reader->SetFileName(file.string());
  try {
    reader->Update();
  } catch (const itk::ExceptionObject&) {
    throw InputError(file.string() +
                     ": cannot read as a vector image (or its data file is missing)");
  }
  const VectorImage* image = reader->GetOutput();
  PlainGeometry g = geometry_of(image);
  const float* p = reinterpret_cast<const float*>(image->GetBufferPointer());
  xyz.assign(p, p + 3 * g.voxel_count());
  return g;
}

PlainFloatImage read_float_image(const fs::path& file) {
  register_formats();
  std::error_code ec;
  if (!fs::exists(file, ec)) throw InputError(file.string() + ": no such file");
  auto reader = itk::ImageFileReader<FloatImage>::New();
  reader->SetFileName(file.string());
  try {
    reader->Update();
  } catch (const itk::ExceptionObject& e) {
    throw InputError(file.string() + ": cannot read as an image (or its data file is missing)");
  }
  PlainFloatImage out;
  const FloatImage* image = reader->GetOutput();
  out.geometry = geometry_of(image);
  const float* p = image->GetBufferPointer();
  out.values.assign(p, p + out.geometry.voxel_count());
  return out;
}

PlainMask read_mask(const fs::path& file) {
  register_formats();
  auto reader = itk::ImageFileReader<MaskImage>::New();
  reader->SetFileName(file.string());
  try {
    reader->Update();
  } catch (const itk::ExceptionObject& e) {
    throw InputError(file.string() + ": cannot read as an image");
  }
  return to_plain(reader->GetOutput());
}

}  // namespace organfit::itkbridge
