#pragma once
// SIGINT / SIGTERM: the run stops at its next check (long loops check often: within a
// second), unwinds through RAII (temporary files removed, no final-named file written)
// and the command exits 130.
namespace organfit {

/// Installs the handlers (once, at start-up of the command).
void install_interrupt_handlers();
/// True once SIGINT or SIGTERM arrived.
bool interrupted();
/// Throws Error(kInterrupted) when interrupted (call in long loops).
void throw_if_interrupted();

/// The last line of defence against third-party aborts on malformed input: GDCM 3.0
/// asserts on some corrupt files that organfit's own checks let through (found by
/// fuzzing). While a ReadingInput is alive, an abort prints
///   organfit: error: FILE: malformed input: the <what> library gave up on it
/// and exits with code 2 (nothing is being written while inputs are read). Installed by
/// install_interrupt_handlers().
class ReadingInput {
 public:
  ReadingInput(const char* file, const char* library);
  ~ReadingInput();
  ReadingInput(const ReadingInput&) = delete;
  ReadingInput& operator=(const ReadingInput&) = delete;
};

}  // namespace organfit
