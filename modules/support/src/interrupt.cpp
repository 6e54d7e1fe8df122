#include "organfit/support/interrupt.h"

#include <csignal>

#include "organfit/support/error.h"

namespace organfit {
namespace {
volatile std::sig_atomic_t g_interrupted = 0;
extern "C" void on_signal(int) { g_interrupted = 1; }  // async-signal-safe: a flag only
}  // namespace

void install_interrupt_handlers() {
  struct sigaction action {};
  action.sa_handler = on_signal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

bool interrupted() { return g_interrupted != 0; }

void throw_if_interrupted() {
  if (g_interrupted) throw Error(ExitCode::kInterrupted, "interrupted (SIGINT or SIGTERM): nothing was written");
}

}  // namespace organfit
