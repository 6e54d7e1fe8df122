#pragma once
// Writing a DICOM Deformable Spatial Registration (REG) object for a planning CT (plain
// GDCM): the fit's deformation as a grid of displacement vectors, as a planning system
// or plastimatch reads it to carry dose or contours between today and planning.
//
// DICOM applies the grid to a point x of the Registered RCS (this object's Frame of
// Reference): x + D(x) is the point of the Source RCS it samples from (PS3.3 C.20.3.1.1;
// no pre- or post-deformation matrix here). Both are the planning CT's Frame of
// Reference: today's anatomy is located in the planning CT's coordinates (the probe is
// registered to the CT). So D(q) = phi^-1(q) - q, the same vectors as the displacement
// field that plastimatch's `warp --xf` reads.
#include <filesystem>
#include <vector>

#include "organfit/dicom/ct_series.h"
#include "organfit/geometry/image_geometry.h"

namespace organfit::dicom {

/// The most grid points a REG object's Vector Grid Data (VR OF, at most 2^32 - 2 bytes)
/// holds: 12 bytes (x, y, z as float) a point.
inline constexpr long long kMostRegistrationGridPoints = 4294967294LL / 12;

struct RegistrationWriteOptions {
  /// Deterministic UIDs and dates (tests): derived from the CT's series UID.
  bool fixed_uids_and_dates = false;
};

/// Writes the REG object: Patient and Study copied from the CT, a Spatial Registration
/// series, the CT's Frame of Reference (registered and source), one Deformable
/// Registration item whose grid is `grid` (its origin, orientation, size and spacing)
/// holding `vectors_mm` (x, y, z per grid point, i fastest, mm, LPS), and a Common
/// Instance Reference to the CT's slices. Explicit VR Little Endian, under a temporary
/// name and renamed. Throws InputError naming the file when it cannot be written, or
/// std::invalid_argument when the vectors do not fill the grid, the grid is not
/// right-handed, or it exceeds what Vector Grid Data holds (4 GB).
/// `vectors_mm` is taken (move it in) and let go once GDCM holds its own copy: on a CT's
/// grid each is hundreds of MB.
void write_deformable_registration(const std::filesystem::path& file, const CtSeries& ct,
                                   const geometry::ImageGeometry& grid,
                                   std::vector<float> vectors_mm,
                                   const RegistrationWriteOptions& options = {});

}  // namespace organfit::dicom
