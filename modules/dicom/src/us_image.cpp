#include "organfit/dicom/us_image.h"

#include <fmt/format.h>
#include <gdcmImageApplyLookupTable.h>
#include <gdcmImageChangePhotometricInterpretation.h>
#include <gdcmImageReader.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmTrace.h>

#include <cstring>

#include "dicom_values.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"

namespace organfit::dicom {
namespace {

/// A little-endian number from an element's bytes (the nested elements of an implicit-VR
/// sequence come without VR).
template <class T>
bool value_of(const gdcm::DataSet& ds, uint16_t group, uint16_t element, T& out) {
  const gdcm::Tag tag(group, element);
  if (!ds.FindDataElement(tag)) return false;
  const gdcm::ByteValue* bv = ds.GetDataElement(tag).GetByteValue();
  if (!bv || bv->GetLength() < sizeof(T)) return false;
  std::memcpy(&out, bv->GetPointer(), sizeof(T));
  return true;
}

}  // namespace

UsImage read_us_image(const std::filesystem::path& file, double pixel_mm) {
  const std::string where = file.string();
  auto fail = [&](const std::string& why) -> void { throw InputError(where + ": " + why); };
  detail::quiet_gdcm();  // e.g. "No spacing value found": ultrasound has regions instead
  if (!detail::safe_for_gdcm(where)) fail("cannot read as DICOM (missing, truncated or not DICOM)");
  gdcm::ImageReader reader;
  reader.SetFileName(where.c_str());
  bool read_ok = false;
  {
    ReadingInput guard(where.c_str(), "GDCM");
    read_ok = reader.Read();
  }
  if (!read_ok) fail("cannot read as a DICOM image");
  // GDCM's filters keep their input in a SmartPointer: it must live on the heap.
  gdcm::SmartPointer<gdcm::Image> input = new gdcm::Image(reader.GetImage());
  gdcm::Image image = *input;
  UsImage out;
  out.photometric =
      gdcm::PhotometricInterpretation::GetPIString(image.GetPhotometricInterpretation());
  while (!out.photometric.empty() && out.photometric.back() == ' ')
    out.photometric.pop_back();
  const unsigned int* dims = image.GetDimensions();
  out.width = static_cast<int>(dims[0]);
  out.height = static_cast<int>(dims[1]);
  out.frames = image.GetNumberOfDimensions() > 2 ? static_cast<int>(dims[2]) : 1;
  if (out.width <= 0 || out.height <= 0 || out.frames <= 0) fail("the image has no pixels");

  // Colour to RGB, then grey.
  const auto pi = image.GetPhotometricInterpretation();
  if (pi == gdcm::PhotometricInterpretation::PALETTE_COLOR) {
    gdcm::ImageApplyLookupTable lut;
    lut.SetInput(*input);
    if (!lut.Apply()) fail("cannot apply its palette");
    image = lut.GetOutput();
  } else if (pi == gdcm::PhotometricInterpretation::YBR_FULL ||
             pi == gdcm::PhotometricInterpretation::YBR_FULL_422) {
    gdcm::ImageChangePhotometricInterpretation change;
    change.SetInput(*input);
    change.SetPhotometricInterpretation(gdcm::PhotometricInterpretation::RGB);
    if (!change.Change()) fail("cannot convert its YBR colour to RGB");
    image = change.GetOutput();
  }
  std::vector<char> buffer(image.GetBufferLength());
  if (!image.GetBuffer(buffer.data())) fail("cannot decode its pixel data");
  const gdcm::PixelFormat& pf = image.GetPixelFormat();
  const int samples = pf.GetSamplesPerPixel(), bits = pf.GetBitsAllocated();
  const bool is_signed = pf.GetPixelRepresentation() == 1;
  if ((samples != 1 && samples != 3) || (bits != 8 && bits != 16))
    fail(fmt::format("{} samples of {} bits: unsupported pixel data", samples, bits));
  const size_t pixels = static_cast<size_t>(out.width) * out.height * out.frames;
  if (buffer.size() < pixels * samples * (bits / 8))
    fail("its pixel data is shorter than its size says");
  const bool planar = samples == 3 && image.GetPlanarConfiguration() == 1;
  auto sample = [&](size_t index) -> double {
    if (bits == 8)
      return is_signed ? static_cast<double>(static_cast<signed char>(buffer[index]))
                       : static_cast<double>(static_cast<unsigned char>(buffer[index]));
    std::uint16_t v;
    std::memcpy(&v, buffer.data() + 2 * index, 2);
    return is_signed ? static_cast<double>(static_cast<std::int16_t>(v)) : static_cast<double>(v);
  };
  out.grey.resize(pixels);
  const size_t frame_pixels = static_cast<size_t>(out.width) * out.height;
  for (size_t p = 0; p < pixels; ++p) {
    if (samples == 1) {
      out.grey[p] = static_cast<float>(sample(p));
    } else {
      const size_t f = p / frame_pixels, q = p % frame_pixels;
      const size_t r = planar ? f * 3 * frame_pixels + q : 3 * p;
      const size_t g = planar ? r + frame_pixels : r + 1, b = planar ? r + 2 * frame_pixels : r + 2;
      out.grey[p] = static_cast<float>(0.299 * sample(r) + 0.587 * sample(g) + 0.114 * sample(b));
    }
  }

  // The physical pixel size from the ultrasound regions.
  const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
  const gdcm::Tag regions_tag(0x0018, 0x6011);
  if (ds.FindDataElement(regions_tag)) {
    gdcm::SmartPointer<gdcm::SequenceOfItems> sq = ds.GetDataElement(regions_tag).GetValueAsSQ();
    for (gdcm::SequenceOfItems::SizeType i = 1;
         sq && i <= sq->GetNumberOfItems() && !out.calibrated; ++i) {
      const gdcm::DataSet& item = sq->GetItem(i).GetNestedDataSet();
      std::uint16_t ux = 0, uy = 0;
      double dx = 0, dy = 0;
      std::uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
      if (value_of(item, 0x0018, 0x6024, ux) && value_of(item, 0x0018, 0x6026, uy) && ux == 3 &&
          uy == 3 && value_of(item, 0x0018, 0x602c, dx) && value_of(item, 0x0018, 0x602e, dy) &&
          dx > 0 && dy > 0) {
        out.calibrated = true;
        out.pixel_mm_x = 10 * dx, out.pixel_mm_y = 10 * dy;  // cm -> mm
        value_of(item, 0x0018, 0x6018, x0), value_of(item, 0x0018, 0x601a, y0);
        value_of(item, 0x0018, 0x601c, x1), value_of(item, 0x0018, 0x601e, y1);
        // Its last pixel as DICOM states it (inclusive), or one past it as some vendors
        // write it (a Philips CX50's 800 x 600 image states x1 = 800): either is within.
        if (!(x0 <= x1 && y0 <= y1 && x1 <= static_cast<std::uint32_t>(out.width) &&
              y1 <= static_cast<std::uint32_t>(out.height)))
          fail(fmt::format(
              "its ultrasound region {} spans pixels ({}, {}) to ({}, {}), not within its {} x "
              "{} pixels",
              i, x0, y0, x1, y1, out.width, out.height));
        out.region = {static_cast<int>(x0), static_cast<int>(y0), static_cast<int>(x1),
                      static_cast<int>(y1)};
      }
    }
  }
  if (pixel_mm > 0) {
    out.pixel_mm_x = out.pixel_mm_y = pixel_mm;
  } else if (!out.calibrated) {
    fail(
        "no calibrated ultrasound region (a Sequence of Ultrasound Regions item with physical "
        "units in cm): "
        "its pixel size is unknown; give it explicitly (--pixel-mm)");
  }
  if (!out.calibrated) out.region = {0, 0, out.width - 1, out.height - 1};
  return out;
}

}  // namespace organfit::dicom
