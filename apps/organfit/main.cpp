// organfit: prepare a radiotherapy session by fitting a particle-system organ model to
// sparse ultrasound points. Subcommands in the style of git / plastimatch, one file each
// in commands/.
//
// Exit codes: 0 success, 1 internal error, 2 bad input (usage, scene, data, a DICOM node
// that cannot be reached, refuses or fails; an output that cannot be written; out of
// memory), 3 ran but did not meet its target. Errors are one line on stderr.
#include <CLI/CLI.hpp>
#include <iostream>
#include <new>
#include <string>

#include "commands/commands.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/log.h"
#include "organfit/support/progress.h"
#include "organfit/support/resources.h"

namespace {

using organfit::ExitCode;

int run_main(int argc, char** argv) {
  CLI::App app{"organfit: fit a particle-system organ model to sparse ultrasound points"};
  app.require_subcommand(1);
  app.fallthrough();
  bool quiet = false, verbose = false;
  app.add_flag("-q,--quiet", quiet, "Only warnings and errors; no progress");
  app.add_flag("-v,--verbose", verbose, "More detail in logs and errors");
  organfit::app::GlobalOptions global;
  app.add_flag("--show-phi", global.show_phi,
               "Allow the patient's name, ID and birth date in the report (report.show_patient); "
               "never in logs");

  std::vector<organfit::app::Command> commands;
  auto add = [&commands](std::vector<organfit::app::Command> more) {
    commands.insert(commands.end(), more.begin(), more.end());
  };
  add(organfit::app::add_run(app, global));
  add(organfit::app::add_schema(app));
  add({organfit::app::add_segment(app)});
  add({organfit::app::add_export(app)});
  add({organfit::app::add_us_points(app)});
  add(organfit::app::add_synth(app));
  add(organfit::app::add_bench(app));
  add(organfit::app::add_dicom(app));

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "organfit: usage: " << e.what() << " (see organfit --help)\n";
    return static_cast<int>(ExitCode::kBadInput);
  }

  organfit::install_interrupt_handlers();
  organfit::setup_logging(quiet     ? organfit::Verbosity::kQuiet
                          : verbose ? organfit::Verbosity::kVerbose
                                    : organfit::Verbosity::kNormal);
  organfit::Progress::set_enabled(!quiet);
  for (const auto& command : commands)
    if (command.cli->parsed()) return command.run();
  return 0;
}

/// Whether the subcommand may touch hundreds of MB or compute for seconds on threads
/// (organs, scans, benchmarks), for which huge pages and a short busy wait are worth their
/// cost: the program started again, 0.12 s of loading and linking its 103 shared libraries
/// a second time. Checking a scene, the schema, the version, a DICOM node by hand and help
/// do not ask for them.
bool wants_runtime_settings(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg.empty() || arg[0] == '-') continue;  // the global flags take no values
    return arg != "validate" && arg != "schema" && arg != "version" && arg != "dicom";
  }
  return false;  // no subcommand: help or a usage error
}

}  // namespace

/// An error as one line: control characters (a library's newlines) as spaces, at most
/// 2,000 characters.
std::string one_line(const char* what) {
  std::string s(what);
  for (auto& c : s)
    if (static_cast<unsigned char>(c) < 0x20) c = ' ';
  return s.size() > 2000 ? s.substr(0, 2000) + "..." : s;
}

int main(int argc, char** argv) {
  if (wants_runtime_settings(argc, argv)) organfit::start_with_runtime_settings(argv);
  organfit::keep_freed_memory();
  int code = 0;
  try {
    code = run_main(argc, argv);
    organfit::mark_finishing();
  } catch (const organfit::Error& e) {
    organfit::mark_finishing();
    std::cerr << (e.code() == ExitCode::kInternal ? "organfit: internal error: "
                                                  : "organfit: error: ")
              << one_line(e.what()) << "\n";
    code = static_cast<int>(e.code());
  } catch (const std::bad_alloc&) {  // out of memory: the environment, not a bug
    organfit::mark_finishing();
    std::cerr << "organfit: error: " << organfit::out_of_memory_message() << "\n";
    code = static_cast<int>(ExitCode::kBadInput);
  } catch (const std::invalid_argument& e) {  // a force term or integrator refused its input
    organfit::mark_finishing();
    std::cerr << "organfit: error: " << one_line(e.what()) << "\n";
    code = static_cast<int>(ExitCode::kBadInput);
  } catch (const std::exception& e) {
    organfit::mark_finishing();
    std::cerr << "organfit: internal error: " << one_line(e.what()) << "\n";
    code = static_cast<int>(ExitCode::kInternal);
  }
  return code;
}
