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

}  // namespace organfit
