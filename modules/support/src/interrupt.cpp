#include "organfit/support/interrupt.h"

#include <fcntl.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>

#include "organfit/support/error.h"

namespace organfit {
namespace {
volatile std::sig_atomic_t g_interrupted = 0;
extern "C" void on_signal(int) {
  g_interrupted = 1;
}  // async-signal-safe: a flag only
}  // namespace

void install_abort_guard();

void install_interrupt_handlers() {
  install_abort_guard();
  struct sigaction action {};
  action.sa_handler = on_signal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

bool interrupted() {
  return g_interrupted != 0;
}

void throw_if_interrupted() {
  if (g_interrupted)
    throw Error(ExitCode::kInterrupted, "interrupted (SIGINT or SIGTERM): nothing was written");
}

}  // namespace organfit

namespace organfit {
namespace {
// Written before the abort handler can run, read only by it (async-signal-safe: plain
// buffers and write(2)).
char g_reading[1024];
const char* g_library = "";
volatile sig_atomic_t g_is_reading = 0;
int g_saved_stderr = -1;  // stderr while a library reads: /dev/null (its assertion texts)

void on_abort(int) {
  if (g_is_reading) {
    if (g_saved_stderr >= 0) ::dup2(g_saved_stderr, 2);
    const char* parts[] = {"organfit: error: ", g_reading, ": malformed input: the ", g_library,
                           " library gave up on it\n"};
    for (const char* p : parts) {
      size_t n = 0;
      while (p[n])
        ++n;
      (void)!::write(2, p, n);
    }
    ::_exit(2);
  }
  std::signal(SIGABRT, SIG_DFL);
  std::raise(SIGABRT);
}
}  // namespace

ReadingInput::ReadingInput(const char* file, const char* library) {
  size_t n = 0;
  for (; file[n] && n + 1 < sizeof g_reading; ++n)
    g_reading[n] = file[n];
  g_reading[n] = 0;
  g_library = library;
  // The library's own assertion text would be a second, cryptic line: silence it while
  // it reads; the abort handler restores stderr and says what happened in one line.
  std::fflush(stderr);
  g_saved_stderr = ::dup(2);
  const int null = ::open("/dev/null", O_WRONLY);
  if (null >= 0) ::dup2(null, 2), ::close(null);
  g_is_reading = 1;
}

ReadingInput::~ReadingInput() {
  g_is_reading = 0;
  if (g_saved_stderr >= 0) ::dup2(g_saved_stderr, 2), ::close(g_saved_stderr), g_saved_stderr = -1;
}

void install_abort_guard() {
  std::signal(SIGABRT, on_abort);
}

}  // namespace organfit
