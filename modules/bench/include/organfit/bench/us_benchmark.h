#pragma once
// `organfit bench us`: the ultrasound segmentation's cost at the sizes: a
// 256 x 256 x 256 volume and a 100-frame tracked sweep of 640 x 480 frames, both of a
// speckled hypoechoic sphere (radius 30 mm) in brighter tissue, with the accuracy found.
#include <nlohmann/json.hpp>

namespace organfit::bench {

struct UsBenchOptions {
  int volume_size = 256;  ///< voxels per side (0.4 mm)
  int frames = 100;
  int threads = 0;  ///< 0: all cores
};

nlohmann::json run_us_benchmark(const UsBenchOptions& options);

}  // namespace organfit::bench
