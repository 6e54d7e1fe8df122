#pragma once
// Tracked ultrasound sweeps in the PLUS toolkit's sequence metafile form (.mha/.mhd):
// a MetaImage header whose frames carry fields `Seq_FrameNNNN_<Name>` (transforms as 16
// numbers, row-major; `<Name>Status`; `Timestamp`; `ImageStatus`), followed by (or
// pointing to) the frames' pixels. Frame numbers may have gaps; images and tracker may
// be in separate files, matched by timestamp.
#include <Eigen/Core>
#include <array>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace organfit::ultrasound {

struct SequenceFrame {
  int index = 0;                              ///< NNNN: the frame's slice in the pixel data
  std::map<std::string, std::string> fields;  ///< <Name> -> value
};

struct SequenceMetafile {
  std::filesystem::path file;
  std::map<std::string, std::string> header;  ///< the other header keys
  std::array<int, 3> size{0, 0, 0};           ///< columns, rows, frames
  std::array<double, 3> spacing_mm{1, 1, 1};
  std::vector<SequenceFrame> frames;  ///< in index order
  std::vector<float> pixels;          ///< grey, size[0] x size[1] x size[2] (empty if none)
};

/// Reads the header and, with `read_pixels`, the pixels (MET_UCHAR, MET_CHAR, MET_USHORT,
/// MET_SHORT, MET_FLOAT, one channel, raw or zlib-compressed, LOCAL or a data file
/// beside it). Throws InputError "FILE: reason" on a malformed header, an unsupported
/// element type, or a missing or short data file.
SequenceMetafile read_sequence_metafile(const std::filesystem::path& file, bool read_pixels = true);

/// A 4x4 transform field's value; throws InputError naming the file, frame and field when
/// it does not hold 16 numbers.
Eigen::Matrix4d transform_field(const SequenceMetafile& sequence, const SequenceFrame& frame,
                                const std::string& name);

/// One tracked frame: its pixels and where they are.
struct TrackedFrame {
  int index = 0;
  double timestamp_s = 0;
  int width = 0, height = 0;
  std::vector<float> pixels;       ///< width x height, row-major
  Eigen::Matrix4d pixel_to_ct_mm;  ///< (column, row, 0, 1) -> CT patient mm
};

struct TrackedSweep {
  std::vector<TrackedFrame> frames;
  int skipped_image_status = 0, skipped_transform_status = 0, skipped_no_pose = 0;
};

struct SweepOptions {
  std::string transform;  ///< e.g. ProbeToTrackerTransform; empty: DefaultFrameTransformName,
                          ///< else the only/first *ToTrackerTransform field
  Eigen::Matrix4d image_to_probe = Eigen::Matrix4d::Identity();  ///< calibration (mm; may scale)
  Eigen::Matrix4d tracker_to_ct = Eigen::Matrix4d::Identity();   ///< registration (rigid)
  double max_time_gap_s = 0.05;  ///< tracker pose matched to an image within this
};

/// Frames of `video` with their poses: from `tracker` matched by nearest timestamp when
/// it is given (a video's own transforms may be placeholders), else from `video` itself. Frames
/// whose image or transform status is not OK, or with no pose within the gap, are skipped
/// (counted). Pixel (c, r) of a frame is at image point (c sx, r sy, 0) mm (the sequence's
/// spacing), then image_to_probe, the tracked transform, tracker_to_ct. Throws InputError on a
/// tracked or registration transform that is not rigid, on no transform field, and when no frame is
/// left.
TrackedSweep assemble_sweep(const SequenceMetafile& video, const SequenceMetafile* tracker,
                            const SweepOptions& options);

/// Writes a sweep as a sequence metafile (raw 8-bit pixels inline, zlib-compressed) with
/// each frame's `ImageToReferenceTransform` (pixel_to_ct with the spacing taken out),
/// status OK and timestamp: what the simulator gives. Atomic.
void write_sequence_metafile(const std::filesystem::path& file, const TrackedSweep& sweep,
                             double pixel_mm);

}  // namespace organfit::ultrasound
