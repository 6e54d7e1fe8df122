#pragma once
// Errors that reach the user, each carrying the process exit code it maps to.
//
// The `organfit` command turns an escaping Error into one line on stderr and its
// exit code; anything else escaping is an internal error (exit 1).
#include <stdexcept>
#include <string>

namespace organfit {

/// Process exit codes of the `organfit` command (documented in the README).
enum class ExitCode : int {
  kOk = 0,            ///< success
  kInternal = 1,      ///< a bug: an unexpected exception
  kBadInput = 2,      ///< usage, scene, unreadable or invalid data
  kTargetNotMet = 3,  ///< ran, but did not meet its target (e.g. a fit that did not converge)
  kInterrupted = 130  ///< stopped by SIGINT/SIGTERM
};

/// An error with a user-facing one-line message and an exit code.
class Error : public std::runtime_error {
 public:
  Error(ExitCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  ExitCode code() const { return code_; }

 private:
  ExitCode code_;
};

/// Bad input: the message names the file, key or element and what is wrong with it.
class InputError : public Error {
 public:
  explicit InputError(const std::string& message) : Error(ExitCode::kBadInput, message) {}
};

/// The run completed but did not reach its target.
class TargetNotMetError : public Error {
 public:
  explicit TargetNotMetError(const std::string& message)
      : Error(ExitCode::kTargetNotMet, message) {}
};

/// A value echoed in a message: at most `max_chars` characters (longer ones end in "..."),
/// control characters and bytes that are not UTF-8 shown as '?', so that an error stays one
/// readable line whatever a file holds. Cut on a UTF-8 character boundary.
std::string echo(const std::string& value, size_t max_chars = 80);

/// The process's address-space limit (ulimit -v) in MB; -1 when none is set.
long long address_space_limit_mb();

/// What a run out of memory says (std::bad_alloc; exit 2, as an environment that cannot
/// hold the run): "out of memory: ...", with the process's address-space limit when one is
/// set (ulimit -v), and that nothing was written. Made without allocating (a static buffer,
/// rewritten by each call).
const char* out_of_memory_message();

/// Maps an exception escaping a command to its exit code (Error: its own; else kInternal).
ExitCode exit_code_of(const std::exception& e);

}  // namespace organfit
