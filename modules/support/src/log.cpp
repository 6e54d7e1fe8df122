#include "organfit/support/log.h"

#include <spdlog/sinks/stdout_color_sinks.h>

namespace organfit {
namespace {
Verbosity g_verbosity = Verbosity::kNormal;
}

void setup_logging(Verbosity verbosity) {
  g_verbosity = verbosity;
  auto logger = spdlog::get("organfit");
  if (!logger) {
    logger = spdlog::stderr_color_mt("organfit");
    spdlog::set_default_logger(logger);
  }
  logger->set_pattern(verbosity == Verbosity::kVerbose ? "[%H:%M:%S.%e] %^%l%$: %v" : "%^%l%$: %v");
  switch (verbosity) {
    case Verbosity::kQuiet:
      logger->set_level(spdlog::level::warn);
      break;
    case Verbosity::kNormal:
      logger->set_level(spdlog::level::info);
      break;
    case Verbosity::kVerbose:
      logger->set_level(spdlog::level::debug);
      break;
  }
}

Verbosity current_verbosity() {
  return g_verbosity;
}

}  // namespace organfit
