#pragma once
// The subcommands of `organfit`, one file each under commands/: each declares its options
// and returns what runs once the command line is parsed (and logging is set up).
#include <CLI/CLI.hpp>
#include <functional>
#include <vector>

namespace organfit::app {

/// A parsed subcommand and what it runs; run() returns the exit code (support/error.h
/// ExitCode) or throws organfit::Error.
struct Command {
  CLI::App* cli = nullptr;
  std::function<int()> run;
};

/// Options every subcommand sees.
struct GlobalOptions {
  bool show_phi = false;  ///< --show-phi: the patient's name and ID may be shown in the report
};

/// `run` and `validate`: a scene.
std::vector<Command> add_run(CLI::App& app, const GlobalOptions& global);
/// `schema` and `version`.
std::vector<Command> add_schema(CLI::App& app);
Command add_segment(CLI::App& app);
Command add_export(CLI::App& app);
Command add_us_points(CLI::App& app);
/// `synth pelvis` and `synth ultrasound`.
std::vector<Command> add_synth(CLI::App& app);
Command add_synth_ultrasound(CLI::App& synth);
/// `bench cohesion|skeleton|ct|us|fit|scale|stability`.
std::vector<Command> add_bench(CLI::App& app);
/// `dicom echo|find|pull|push`.
std::vector<Command> add_dicom(CLI::App& app);

}  // namespace organfit::app
