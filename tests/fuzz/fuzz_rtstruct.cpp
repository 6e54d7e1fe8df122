// The RT Structure Set reader on arbitrary bytes, and the rasterisation of what it reads
// onto a small CT grid.
#include "fuzz_util.h"
#include "organfit/dicom/structure_set.h"
#include "organfit/support/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto file = bytes_to_file(data, size, ".dcm");
  try {
    const organfit::dicom::StructureSet rtss = organfit::dicom::read_rtstruct(file);
    organfit::dicom::CtSeries ct;
    ct.geometry.size = {32, 32, 8};
    ct.geometry.spacing_mm = Eigen::Vector3d(2, 2, 3);
    ct.frame_of_reference_uid = rtss.frame_of_reference_uid;
    for (int k = 0; k < 8; ++k)
      ct.slices.push_back({"1.2.3." + std::to_string(k), "", Eigen::Vector3d(0, 0, 3.0 * k), {}});
    for (const auto& roi : rtss.rois)
      (void)organfit::dicom::rasterise_roi(rtss, roi.name, ct, "fuzz");
  } catch (const organfit::Error&) {
  }
  return 0;
}
