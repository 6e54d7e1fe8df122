// The scene parser and organfit's rules on arbitrary text.
#include <cstdint>
#include <string>

#include "organfit/pipeline/scene_schema.h"
#include "organfit/support/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const organfit::config::Scene scene = organfit::config::parse_scene(
        text, "/nonexistent/fuzz.yaml", organfit::pipeline::scene_schema());
    organfit::pipeline::check_scene_rules(scene);
    (void)scene.resolved_yaml();
  } catch (const organfit::Error&) {
  }
  return 0;
}
