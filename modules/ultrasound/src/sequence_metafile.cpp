#include "organfit/ultrasound/sequence_metafile.h"

#include <fmt/format.h>
#include <zlib.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::ultrasound {
namespace {

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  const auto e = s.find_last_not_of(" \t\r");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

std::vector<double> numbers_of(const std::string& s) {
  std::istringstream in(s);
  std::vector<double> v;
  double x;
  while (in >> x)
    v.push_back(x);
  return v;
}

bool rigid(const Eigen::Matrix4d& m) {
  const Eigen::Matrix3d r = m.topLeftCorner<3, 3>();
  return (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-3 &&
         r.determinant() > 0 && std::abs(m(3, 0)) + std::abs(m(3, 1)) + std::abs(m(3, 2)) < 1e-9 &&
         std::abs(m(3, 3) - 1) < 1e-9;
}

}  // namespace

SequenceMetafile read_sequence_metafile(const fs::path& file, bool read_pixels) {
  const std::string where = file.string();
  auto fail = [&](const std::string& why) -> void { throw InputError(where + ": " + why); };
  std::ifstream in(file, std::ios::binary);
  if (!in) fail("cannot read the file");
  SequenceMetafile s;
  s.file = file;
  std::map<int, SequenceFrame> frames;
  std::string line, data_file;
  bool header_done = false;
  while (std::getline(in, line)) {
    const auto eq = line.find('=');
    if (eq == std::string::npos) continue;
    const std::string key = trim(line.substr(0, eq)), value = trim(line.substr(eq + 1));
    if (key.rfind("Seq_Frame", 0) == 0) {
      const auto underscore = key.find('_', 9);
      if (underscore == std::string::npos) fail("malformed frame field '" + echo(key) + "'");
      const int index = std::atoi(key.substr(9, underscore - 9).c_str());
      frames[index].index = index;
      frames[index].fields[key.substr(underscore + 1)] = value;
    } else {
      s.header[key] = value;
    }
    if (key == "ElementDataFile") {
      data_file = value;
      header_done = true;
      break;
    }
  }
  if (!header_done) fail("no ElementDataFile line: not a MetaImage header");
  for (auto& [index, frame] : frames)
    s.frames.push_back(std::move(frame));
  const std::vector<double> dims = numbers_of(s.header["DimSize"]);
  if (dims.size() < 2 || dims.size() > 3) fail("DimSize must have 2 or 3 numbers");
  for (const double v : dims)  // found by fuzzing: 7.8e42 overflowed the int it was cast to
    if (!(v >= 1 && v <= 100000 && v == std::floor(v)))
      fail("DimSize must hold whole numbers from 1 to 100000");
  for (size_t d = 0; d < 3; ++d)
    s.size[d] = d < dims.size() ? static_cast<int>(dims[d]) : 1;
  if (1.0 * s.size[0] * s.size[1] * s.size[2] > 2e9) fail("DimSize is larger than 2e9 pixels");
  const std::vector<double> spacing = numbers_of(s.header["ElementSpacing"]);
  for (size_t d = 0; d < 3 && d < spacing.size(); ++d)
    s.spacing_mm[d] = spacing[d];
  if (!read_pixels) return s;

  const std::string type = s.header["ElementType"];
  const int channels = s.header.count("ElementNumberOfChannels")
                           ? std::atoi(s.header["ElementNumberOfChannels"].c_str())
                           : 1;
  if (channels != 1) fail(fmt::format("{} channels: only grey images are supported", channels));
  size_t bytes_per = 0;
  if (type == "MET_UCHAR" || type == "MET_CHAR")
    bytes_per = 1;
  else if (type == "MET_USHORT" || type == "MET_SHORT")
    bytes_per = 2;
  else if (type == "MET_FLOAT")
    bytes_per = 4;
  else
    fail("element type '" + type +
         "' is not supported (MET_UCHAR, MET_CHAR, MET_USHORT, MET_SHORT, MET_FLOAT)");
  const size_t count = static_cast<size_t>(s.size[0]) * s.size[1] * s.size[2];
  std::string raw;
  if (data_file == "LOCAL") {
    raw.assign(std::istreambuf_iterator<char>(in), {});
  } else {
    const fs::path data = file.parent_path() / data_file;
    std::error_code ec;
    if (data_file.empty() ||
        !fs::is_regular_file(data, ec))  // found by fuzzing: a folder named here
      fail("its data file " +
           (data_file.empty() ? std::string("(none named)") : data.filename().string()) +
           " is missing");
    std::ifstream d(data, std::ios::binary);
    if (!d) fail("its data file " + data.filename().string() + " is missing");
    raw.assign(std::istreambuf_iterator<char>(d), {});
  }
  if (s.header["CompressedData"] == "True") {
    std::string out(count * bytes_per, '\0');
    uLongf size = static_cast<uLongf>(out.size());
    if (uncompress(reinterpret_cast<Bytef*>(out.data()), &size,
                   reinterpret_cast<const Bytef*>(raw.data()),
                   static_cast<uLong>(raw.size())) != Z_OK ||
        size != out.size())
      fail("its compressed pixel data does not inflate to DimSize");
    raw = std::move(out);
  }
  if (raw.size() < count * bytes_per)
    fail(fmt::format("pixel data holds {} bytes, DimSize needs {}", raw.size(), count * bytes_per));
  s.pixels.resize(count);
  const auto* p = reinterpret_cast<const unsigned char*>(raw.data());
  for (size_t v = 0; v < count; ++v) {
    if (type == "MET_UCHAR")
      s.pixels[v] = p[v];
    else if (type == "MET_CHAR")
      s.pixels[v] = static_cast<signed char>(p[v]);
    else if (type == "MET_USHORT")
      s.pixels[v] = static_cast<float>(p[2 * v] | (p[2 * v + 1] << 8));
    else if (type == "MET_SHORT")
      s.pixels[v] = static_cast<std::int16_t>(p[2 * v] | (p[2 * v + 1] << 8));
    else
      std::memcpy(&s.pixels[v], p + 4 * v, 4);
  }
  return s;
}

Eigen::Matrix4d transform_field(const SequenceMetafile& s, const SequenceFrame& f,
                                const std::string& name) {
  const auto it = f.fields.find(name);
  const std::vector<double> v =
      it == f.fields.end() ? std::vector<double>{} : numbers_of(it->second);
  if (v.size() != 16)
    throw InputError(
        fmt::format("{}: frame {}: {} does not hold 16 numbers", s.file.string(), f.index, name));
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c)
      m(r, c) = v[static_cast<size_t>(4 * r + c)];
  return m;
}

TrackedSweep assemble_sweep(const SequenceMetafile& video, const SequenceMetafile* tracker,
                            const SweepOptions& o) {
  const std::string where = video.file.string();
  if (!rigid(o.tracker_to_ct))
    throw InputError(where + ": the tracker-to-CT registration is not a rigid transform");
  // Which transform: as named, else the file's default, else the first *ToTracker one.
  auto find_name = [&](const SequenceMetafile& s) -> std::string {
    if (!o.transform.empty()) return o.transform;
    const auto def = s.header.find("DefaultFrameTransformName");
    if (def != s.header.end() && !def->second.empty()) return def->second;
    // Prefer the probe's pose; else the only (or first) tracked tool.
    const std::string suffix = "ToTrackerTransform";
    std::string first;
    for (const auto& f : s.frames)
      for (const auto& [k, v] : f.fields) {
        if (k.size() <= suffix.size() ||
            k.compare(k.size() - suffix.size(), suffix.size(), suffix) != 0)
          continue;
        if (k == "ProbeToTrackerTransform") return k;
        if (first.empty()) first = k;
      }
    if (!first.empty()) return first;
    return {};
  };
  // A tracker file, when given, has the poses (the video's own may be placeholders).
  const bool in_video = !tracker;
  const SequenceMetafile* poses = in_video ? &video : tracker;
  if (!poses) throw InputError(where + ": no transform in the frames and no tracker file given");
  const std::string name = find_name(*poses);
  if (name.empty())
    throw InputError(poses->file.string() +
                     ": no frame transform field (e.g. ProbeToTrackerTransform)");

  auto timestamp = [](const SequenceFrame& f) {
    const auto it = f.fields.find("Timestamp");
    return it == f.fields.end() ? std::nan("") : std::atof(it->second.c_str());
  };
  auto status_ok = [&](const SequenceFrame& f) {
    const auto it = f.fields.find(name + "Status");
    return it == f.fields.end() || it->second == "OK";
  };
  TrackedSweep sweep;
  const int w = video.size[0], h = video.size[1];
  Eigen::Matrix4d scale = Eigen::Matrix4d::Identity();
  scale(0, 0) = video.spacing_mm[0], scale(1, 1) = video.spacing_mm[1];
  for (const auto& f : video.frames) {
    const auto image_status = f.fields.find("ImageStatus");
    if (image_status != f.fields.end() && image_status->second != "OK") {
      ++sweep.skipped_image_status;
      continue;
    }
    if (f.index < 0 || f.index >= video.size[2]) continue;
    const SequenceFrame* pose = nullptr;
    if (in_video) {
      pose = &f;
    } else {
      const double t = timestamp(f);
      double best = o.max_time_gap_s;
      for (const auto& g : tracker->frames) {
        const double dt = std::abs(timestamp(g) - t);
        if (dt <= best) best = dt, pose = &g;
      }
      if (!pose) {
        ++sweep.skipped_no_pose;
        continue;
      }
    }
    if (!status_ok(*pose)) {
      ++sweep.skipped_transform_status;
      continue;
    }
    const Eigen::Matrix4d tracked = transform_field(*poses, *pose, name);
    if (!rigid(tracked))
      throw InputError(fmt::format("{}: frame {}: {} is not a rigid transform",
                                   poses->file.string(), pose->index, name));
    TrackedFrame frame;
    frame.index = f.index;
    frame.timestamp_s = timestamp(f);
    frame.width = w, frame.height = h;
    if (!video.pixels.empty()) {
      const auto first =
          video.pixels.begin() + static_cast<long>(static_cast<size_t>(f.index) * w * h);
      frame.pixels.assign(first, first + static_cast<long>(static_cast<size_t>(w) * h));
    }
    frame.pixel_to_ct_mm = o.tracker_to_ct * tracked * o.image_to_probe * scale;
    sweep.frames.push_back(std::move(frame));
  }
  if (sweep.frames.empty())
    throw InputError(fmt::format(
        "{}: no usable frame ({} with image status not OK, {} with transform status not OK, "
        "{} without a tracker pose within {} s)",
        where, sweep.skipped_image_status, sweep.skipped_transform_status, sweep.skipped_no_pose,
        o.max_time_gap_s));
  return sweep;
}

void write_sequence_metafile(const fs::path& file, const TrackedSweep& sweep, double pixel_mm) {
  if (sweep.frames.empty()) throw InputError(file.string() + ": no frames to write");
  const int w = sweep.frames.front().width, h = sweep.frames.front().height;
  std::ostringstream header;
  header << "ObjectType = Image\nNDims = 3\nAnatomicalOrientation = RAI\nBinaryData = True\n"
         << "BinaryDataByteOrderMSB = False\nCenterOfRotation = 0 0 0\nCompressedData = True\n";
  std::string raw;
  raw.reserve(static_cast<size_t>(w) * h * sweep.frames.size());
  for (const auto& f : sweep.frames)
    for (float v : f.pixels)
      raw.push_back(static_cast<char>(static_cast<unsigned char>(std::clamp(v, 0.0f, 255.0f))));
  uLongf size = compressBound(static_cast<uLong>(raw.size()));
  std::string packed(size, '\0');
  compress2(reinterpret_cast<Bytef*>(packed.data()), &size,
            reinterpret_cast<const Bytef*>(raw.data()), static_cast<uLong>(raw.size()), 6);
  packed.resize(size);
  header << "CompressedDataSize = " << packed.size() << "\n"
         << "DimSize = " << w << " " << h << " " << sweep.frames.size() << "\n"
         << "ElementNumberOfChannels = 1\nElementSpacing = " << pixel_mm << " " << pixel_mm
         << " 1\n"
         << "ElementType = MET_UCHAR\nOffset = 0 0 0\nTransformMatrix = 1 0 0 0 1 0 0 0 1\n"
         << "UltrasoundImageOrientation = MF\nUltrasoundImageType = BRIGHTNESS\n"
         << "DefaultFrameTransformName = ImageToReferenceTransform\n";
  Eigen::Matrix4d unscale = Eigen::Matrix4d::Identity();
  unscale(0, 0) = unscale(1, 1) = 1.0 / pixel_mm;
  for (size_t n = 0; n < sweep.frames.size(); ++n) {
    const Eigen::Matrix4d m = sweep.frames[n].pixel_to_ct_mm * unscale;  // image mm -> CT mm
    header << fmt::format("Seq_Frame{:04d}_ImageToReferenceTransform =", n);
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c)
        header << fmt::format(" {:.6g}", m(r, c));
    header << fmt::format("\nSeq_Frame{:04d}_ImageToReferenceTransformStatus = OK\n", n)
           << fmt::format("Seq_Frame{:04d}_Timestamp = {:.3f}\n", n, sweep.frames[n].timestamp_s)
           << fmt::format("Seq_Frame{:04d}_ImageStatus = OK\n", n);
  }
  header << "ElementDataFile = LOCAL\n";
  AtomicFile out(file, true);
  out.stream() << header.str();
  out.stream().write(packed.data(), static_cast<std::streamsize>(packed.size()));
  out.commit();
}

}  // namespace organfit::ultrasound
