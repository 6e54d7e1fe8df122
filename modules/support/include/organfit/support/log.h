#pragma once
// Levelled logging on stderr (spdlog). stdout is kept for machine-readable output
// (benchmark JSON, `organfit schema`), so logs never mix into it.
#include <spdlog/spdlog.h>

namespace organfit {

enum class Verbosity { kQuiet, kNormal, kVerbose };

/// Sets up the process-wide logger on stderr. kQuiet shows warnings and errors only.
void setup_logging(Verbosity verbosity);

/// The verbosity last passed to setup_logging (kNormal before any call).
Verbosity current_verbosity();

}  // namespace organfit
