#pragma once
// SIGINT / SIGTERM, and the run's wall budget: the run stops at its next check (long
// loops check often), unwinds through RAII (temporary files removed, no final-named file
// written) and the command exits 130 (3 when the budget ran out).
//
// Where no check comes in time (inside a library call: ITK, GDCM, VTK; a loop of a
// module that knows nothing of signals), a watchdog thread ends the process itself
// kStopGrace after the signal: it removes every path registered as "partial" (staging
// folders, temporary files, folders created for outputs), prints the same one line and
// exits with the same code. So every stage stops within a second and leaves nothing
// partial, whether or not its loops check. A commit in progress (ScopedCommit) is let
// finish first: it only renames, in milliseconds.
#include <filesystem>
#include <string>

namespace organfit {

/// How long after a signal the watchdog waits for the run to stop by itself (s).
constexpr double kStopGrace = 0.5;

/// Installs the handlers and the watchdog (once, at start-up of the command, before any
/// other thread exists: the signals are taken by the watchdog thread alone). Also
/// std::terminate's handler: an exception that cannot unwind to the command (thrown out of
/// an OpenMP region, where the runtime cannot carry it; out of memory, mostly) ends the
/// process as a stop does, at once: partial outputs removed, one line ("organfit: error:
/// out of memory: ..."), its exit code (2 for memory, an Error's own, else 1).
void install_interrupt_handlers();
/// True once SIGINT or SIGTERM arrived, or the wall budget ran out (both as the watchdog
/// saw them: within 20 ms).
bool interrupted();
/// Throws Error(kInterrupted) when interrupted, Error(kTargetNotMet) when the wall budget
/// ran out (call in long loops).
void throw_if_interrupted();
/// The whole command's wall budget (s) from now; 0: none. When it runs out the command
/// stops as on a signal, exit 3, the message naming `what` (e.g. "scene.max_wall_s").
void set_wall_budget(double seconds, const char* what);
/// Tells the watchdog that the command is ending by itself (its message is about to be
/// printed): it no longer steps in. If the watchdog has already begun its forced exit, this
/// does not return (the watchdog prints the one line and ends the process), so a stop
/// never prints two lines.
void mark_finishing();

/// A path that is partial while this lives (a staging folder, a temporary file, a folder
/// made for outputs): removed by the watchdog if the process is stopped. `only_if_empty`:
/// a folder removed only when empty (one that outputs were made in).
class PartialPath {
 public:
  explicit PartialPath(std::filesystem::path path, bool only_if_empty = false);
  ~PartialPath();
  PartialPath(const PartialPath&) = delete;
  PartialPath& operator=(const PartialPath&) = delete;

 private:
  int id_;
};

/// Runs `shell_command` with /bin/sh as a child that takes SIGINT and SIGTERM as usual
/// (its signals are not blocked as this process's are) and returns its wait status, as
/// std::system does. On a stop the child gets SIGTERM at once (from the watchdog, or here
/// when this thread sees the stop first), and this returns (throwing the stop) only once
/// every process of its group has ended, so that none writes after the caller has removed
/// its partial outputs; one that outlasts kStopGrace is killed by the watchdog.
int run_command(const std::string& shell_command);

/// While alive, the watchdog waits instead of stopping the process (outputs being moved
/// into place).
class ScopedCommit {
 public:
  ScopedCommit();
  ~ScopedCommit();
  ScopedCommit(const ScopedCommit&) = delete;
  ScopedCommit& operator=(const ScopedCommit&) = delete;
};

/// The last line of defence against third-party crashes on malformed input: GDCM 3.0
/// asserts on some corrupt files that organfit's own checks let through (found by
/// fuzzing), VTK 9.1's PLY reader faults on a header cut short. While a ReadingInput is
/// alive, the library's messages are kept off stderr, and an abort or a fault ends the
/// process as a stop does (partial outputs removed) with
///   organfit: error: FILE: malformed input: the <what> library gave up on it
/// and exit code 2. Installed by install_interrupt_handlers(), with the same ending for
/// any other crash (exit 1).
class ReadingInput {
 public:
  ReadingInput(const char* file, const char* library);
  ~ReadingInput();
  ReadingInput(const ReadingInput&) = delete;
  ReadingInput& operator=(const ReadingInput&) = delete;
};

}  // namespace organfit
