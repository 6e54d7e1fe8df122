#include "organfit/support/interrupt.h"

#include <dirent.h>
#include <fcntl.h>
#include <pthread.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <exception>
#include <initializer_list>
#include <map>
#include <mutex>
#include <new>
#include <set>
#include <string>
#include <thread>

#include "organfit/support/error.h"

namespace organfit {
namespace {

enum Stop : int { kRunning = 0, kSignalled = 1, kOutOfTime = 2, kFailed = 3 };
std::atomic<int> g_stop{kRunning};
// Who ends a stopped process and prints its one line: the run's thread (kByRun, once it
// is printing its message) or the watchdog (kByWatchdog, its forced exit). Claimed once.
enum Ender : int { kNobody = 0, kByRun = 1, kByWatchdog = 2 };
std::atomic<int> g_ender{kNobody};
std::atomic<int> g_committing{0};
std::atomic<double> g_deadline_s{0};  // on the steady clock; 0: none
// Set while the watchdog removes partial outputs before it ends the process: a library
// writing into them may then fail an assertion, which is not the run's error.
std::atomic<bool> g_ending{false};
// kFailed: a failure that could not unwind to the command (an exception out of an OpenMP
// region or a worker thread, a crash): its message (one line) and exit code, set once
// (record_failure).
char g_failure[1024];
std::atomic<int> g_failure_code{static_cast<int>(ExitCode::kInternal)};
// Said after a crash when the process's address space is limited: a library that failed to
// get memory and went on is the likely cause. Made at start-up (no formatting then).
char g_crash_hint[160];
const char* g_budget_name = "the wall budget";
double g_budget_s = 0;

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

struct Partial {
  std::filesystem::path path;
  bool only_if_empty = false;
};
std::mutex g_partial_mutex;
std::map<int, Partial> g_partial;  // by registration order: later ones inside earlier ones
int g_next_id = 0;

std::mutex g_children_mutex;
std::set<pid_t> g_children;  // run_command's children still running

void stop_children(int sig = SIGTERM) {
  std::lock_guard<std::mutex> lock(g_children_mutex);
  for (pid_t pid : g_children)
    ::kill(-pid, sig);  // the child's whole process group: the shell and what it runs
}

/// Reaps what has ended of the process group `pid` and tells whether any of it is left.
/// Its members orphaned by the shell's end are ours to reap (we are their subreaper).
bool group_left(pid_t pid) {
  while (::waitpid(-pid, nullptr, WNOHANG) > 0) {
  }
  return ::kill(-pid, 0) == 0;
}

/// Whether any child's process group still has a process.
bool children_left() {
  std::lock_guard<std::mutex> lock(g_children_mutex);
  for (pid_t pid : g_children)
    if (group_left(pid)) return true;
  return false;
}

int stop_code() {
  switch (g_stop.load()) {
    case kOutOfTime:
      return static_cast<int>(ExitCode::kTargetNotMet);
    case kFailed:
      return g_failure_code.load();
    default:
      return static_cast<int>(ExitCode::kInterrupted);
  }
}

std::string stop_message() {
  if (g_stop.load() == kFailed) return g_failure;
  if (g_stop.load() == kOutOfTime) {
    char text[256];
    std::snprintf(text, sizeof text,
                  "the run took longer than %s (%g s) and was stopped: nothing was written",
                  g_budget_name, g_budget_s);
    return text;
  }
  return "interrupted (SIGINT or SIGTERM): nothing was written";
}

/// Records a failure that cannot unwind (the first one only: a second, on another thread
/// or from the ending itself, does not overwrite it): its line from `parts` (control
/// characters as spaces) and its exit code, then the stop the watchdog ends the process on.
/// No memory is asked for (there may be none, or the heap may be broken): it may run in a
/// signal handler. Should the watchdog itself be the thread that failed, SIGALRM's default
/// ends the process 5 s later: never a hang.
void record_failure(std::initializer_list<const char*> parts, int code) {
  static std::atomic<bool> recorded{false};
  if (recorded.exchange(true)) return;
  size_t n = 0;
  for (const char* p : parts)
    for (; *p && n + 1 < sizeof g_failure; ++p)
      g_failure[n++] = static_cast<unsigned char>(*p) < 0x20 ? ' ' : *p;
  g_failure[n] = 0;
  g_failure_code = code;
  int running = kRunning;
  g_stop.compare_exchange_strong(running, kFailed);  // a stop already under way stands
  ::alarm(5);
}

/// Removes `name` (relative to the folder `dir_fd`, or a path), a file or a folder with all
/// it holds, by system calls alone: no memory is asked for (the process may be ending for
/// the lack of it, or for a heap a crash left broken). Not across symbolic links.
void remove_tree(int dir_fd, const char* name, int depth) {
  if (::unlinkat(dir_fd, name, 0) == 0 || errno == ENOENT) return;
  if (depth > 64) return;
  const int fd = ::openat(dir_fd, name, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
  if (fd < 0) return;
  alignas(8) char entries[2048];
  // Listed again from the start while something was removed: removing entries while a
  // listing goes on may make it skip some.
  for (int pass = 0; pass < 8; ++pass) {
    bool removed = false;
    ::lseek(fd, 0, SEEK_SET);
    for (ssize_t n; (n = ::getdents64(fd, entries, sizeof entries)) > 0;)
      for (ssize_t at = 0; at < n;) {
        const auto* e = reinterpret_cast<const struct dirent64*>(entries + at);
        at += e->d_reclen;
        if (std::strcmp(e->d_name, ".") == 0 || std::strcmp(e->d_name, "..") == 0) continue;
        remove_tree(fd, e->d_name, depth + 1);
        removed = true;
      }
    if (!removed) break;
  }
  ::close(fd);
  ::unlinkat(dir_fd, name, AT_REMOVEDIR);
}

/// The watchdog: takes SIGINT and SIGTERM (blocked in every other thread), watches the
/// wall budget, and ends a process that has not stopped by itself kStopGrace later.
void watchdog(sigset_t signals) {
  double stop_at = 0;
  for (;;) {
    timespec wait{0, 20'000'000};  // 20 ms
    const int sig = sigtimedwait(&signals, nullptr, &wait);
    if (sig == SIGINT || sig == SIGTERM) {
      int expected = kRunning;
      g_stop.compare_exchange_strong(expected, kSignalled);
    }
    const double deadline = g_deadline_s.load();
    if (deadline > 0 && now_s() > deadline) {
      int expected = kRunning;
      g_stop.compare_exchange_strong(expected, kOutOfTime);
    }
    if (g_stop.load() == kRunning) continue;
    if (stop_at == 0) {
      // A failure cannot unwind: ended at once.
      stop_at = now_s() + (g_stop.load() == kFailed ? 0.0 : kStopGrace);
      stop_children();
    }
    if (now_s() < stop_at || g_committing.load() > 0) continue;
    int nobody = kNobody;
    if (!g_ender.compare_exchange_strong(nobody, kByWatchdog)) continue;  // the run ends itself
    // The run did not stop in time: remove what is partial, innermost first, and end.
    // A child still stopping could write into it again (a slow machine: a work folder
    // was left behind): it is killed first.
    stop_children(SIGKILL);
    for (int i = 0; i < 50 && children_left(); ++i)  // at most 0.5 s: they are reaped
      ::usleep(10'000);
    {
      std::lock_guard<std::mutex> lock(g_partial_mutex);
      g_ending = true;
      for (auto it = g_partial.rbegin(); it != g_partial.rend(); ++it) {
        const char* path = it->second.path.c_str();
        if (it->second.only_if_empty) {
          ::rmdir(path);  // fails, as wanted, on a folder that holds something
          continue;
        }
        // Moved aside first, then removed: the run's thread may still be writing into it
        // (a file made between the removal's listing and its last rmdir left the folder
        // behind), and a path it opens after the move no longer leads there.
        // Named for this process: one left by an earlier crash would make the move fail.
        char aside[4096];
        const int n = std::snprintf(aside, sizeof aside, "%s.removing-%ld", path,
                                    static_cast<long>(::getpid()));
        const bool moved =
            n > 0 && static_cast<size_t>(n) < sizeof aside && ::rename(path, aside) == 0;
        remove_tree(AT_FDCWD, moved ? aside : path, 0);
      }
      const int code = stop_code();
      const char* prefix = code == static_cast<int>(ExitCode::kInternal)
                               ? "organfit: internal error: "
                               : "organfit: error: ";
      (void)!::write(2, prefix, std::strlen(prefix));
      if (g_stop.load() == kFailed) {  // written without asking for memory
        (void)!::write(2, g_failure, std::strlen(g_failure));
      } else {
        const std::string message = stop_message();
        (void)!::write(2, message.data(), message.size());
      }
      (void)!::write(2, "\n", 1);
      ::_exit(code);
    }
  }
}

}  // namespace

void install_abort_guard();

namespace {

/// std::terminate's handler: an exception that could not unwind to the command (thrown
/// on an OpenMP worker, or out of an OpenMP region, where the runtime cannot carry it)
/// ends the process as a stop does, at once: the partial outputs removed by the watchdog,
/// one line, the exception's exit code (out of memory: 2, as out_of_memory_message says).
[[noreturn]] void on_terminate() {
  // Without an exception: a library called std::terminate (ITK does when it cannot start
  // its threads: their stacks are address space too).
  const char* message = "the process was terminated (std::terminate)";
  const char* hint = g_crash_hint;
  const char* tail = "; nothing was written";
  int code = static_cast<int>(ExitCode::kInternal);
  try {
    if (const std::exception_ptr e = std::current_exception()) std::rethrow_exception(e);
  } catch (const std::bad_alloc&) {
    message = out_of_memory_message(), code = static_cast<int>(ExitCode::kBadInput);
    hint = tail = "";  // its message says so
  } catch (const Error& e) {
    message = e.what(), code = static_cast<int>(e.code()), hint = tail = "";
  } catch (const std::exception& e) {
    message = e.what(), hint = "";
  } catch (...) {
    message = "an unknown exception", hint = "";
  }
  record_failure({message, hint, tail}, code);
  for (;;)
    ::pause();  // the watchdog ends the process
}
}  // namespace

void install_interrupt_handlers() {
  static bool installed = false;
  if (installed) return;
  installed = true;
  install_abort_guard();
  std::set_terminate(on_terminate);
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);  // inherited by every later thread
  // run_command's shell may end before what it runs (dash forks a command rather than exec
  // it): the orphans come to us rather than to init, which in a container may never reap
  // them, so that the end of the whole group can be seen.
  ::prctl(PR_SET_CHILD_SUBREAPER, 1);
  std::thread(watchdog, signals).detach();
}

bool interrupted() {
  return g_stop.load() != kRunning;  // the watchdog sets it, for signals and the budget alike
}

void throw_if_interrupted() {
  if (!interrupted()) return;
  throw Error(static_cast<ExitCode>(stop_code()), stop_message());
}

void set_wall_budget(double seconds, const char* what) {
  g_budget_name = what;
  g_budget_s = seconds;
  g_deadline_s.store(seconds > 0 ? now_s() + seconds : 0);
}

int run_command(const std::string& shell_command) {
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  sigset_t none, defaults;
  sigemptyset(&none);
  sigemptyset(&defaults);
  sigaddset(&defaults, SIGINT);
  sigaddset(&defaults, SIGTERM);
  posix_spawnattr_setsigmask(&attr, &none);
  posix_spawnattr_setsigdefault(&attr, &defaults);
  posix_spawnattr_setpgroup(&attr, 0);  // a group of its own, signalled as a whole
  posix_spawnattr_setflags(&attr,
                           POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF | POSIX_SPAWN_SETPGROUP);
  const char* argv[] = {"sh", "-c", shell_command.c_str(), nullptr};
  pid_t pid = 0;
  int status = -1;
  {
    std::lock_guard<std::mutex> lock(g_children_mutex);
    // Not once stopped: the watchdog signals the children it knows (under this lock), and
    // one spawned after it did would outlive the stop.
    if (interrupted()) {
      posix_spawnattr_destroy(&attr);
      throw_if_interrupted();
    }
    const int rc =
        posix_spawn(&pid, "/bin/sh", nullptr, &attr, const_cast<char* const*>(argv), environ);
    posix_spawnattr_destroy(&attr);
    if (rc != 0) return -1;
    g_children.insert(pid);
  }
  bool told = false;  // the watchdog may have told the group already
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (interrupted() && !told) ::kill(-pid, SIGTERM), told = true;
    ::usleep(20'000);
  }
  // What the shell ran may outlive it by its own clean-up (dash forks a command rather
  // than exec it): wait for the whole group to go before the caller removes what it wrote
  // into. Not bounded here: kStopGrace after the stop the watchdog kills the group and ends
  // the process itself.
  while (group_left(pid) && interrupted())
    ::usleep(10'000);
  {
    std::lock_guard<std::mutex> lock(g_children_mutex);
    g_children.erase(pid);
  }
  throw_if_interrupted();
  return status;
}

void mark_finishing() {
  int ender = kNobody;
  if (g_ender.compare_exchange_strong(ender, kByRun) || ender == kByRun) return;
  // The watchdog is ending the process (its forced exit prints the stop's one line): a
  // second line from here would repeat it.
  for (;;)
    ::pause();
}

PartialPath::PartialPath(std::filesystem::path path, bool only_if_empty) {
  std::lock_guard<std::mutex> lock(g_partial_mutex);
  id_ = g_next_id++;
  g_partial[id_] = {std::move(path), only_if_empty};
}

PartialPath::~PartialPath() {
  std::lock_guard<std::mutex> lock(g_partial_mutex);
  g_partial.erase(id_);
}

ScopedCommit::ScopedCommit() {
  ++g_committing;
}

ScopedCommit::~ScopedCommit() {
  --g_committing;
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

/// A crash (a fault, an abort, a failed assertion) ends the process as a stop does: the
/// watchdog removes the partial outputs (by system calls alone: a heap the crash broke is
/// not used) and says so in one line. While a library reads an input (ReadingInput), the
/// input is what it gave up on: exit 2 naming it; else an internal error, exit 1. This
/// thread waits for the watchdog; should the watchdog itself be the one that crashed,
/// SIGALRM's default ends the process 5 s later.
[[noreturn]] void on_crash(int sig) {
  // The watchdog is removing what this thread was writing (GDCM asserts that the file it
  // opens is open): it ends the process itself in a moment, with its own message.
  if (!g_ending.load()) {
    if (g_is_reading) {
      if (g_saved_stderr >= 0) ::dup2(g_saved_stderr, 2);  // the library's text was silenced
      record_failure({g_reading, ": malformed input: the ", g_library, " library gave up on it"},
                     static_cast<int>(ExitCode::kBadInput));
    } else {
      record_failure({"the process crashed (",
                      sig == SIGSEGV  ? "a segmentation fault"
                      : sig == SIGBUS ? "a bus error"
                      : sig == SIGFPE ? "an arithmetic fault"
                      : sig == SIGILL ? "an illegal instruction"
                                      : "an abort",
                      ")", g_crash_hint, "; nothing was written"},
                     static_cast<int>(ExitCode::kInternal));
    }
  }
  for (;;)
    ::pause();
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
  if (const long long mb = address_space_limit_mb(); mb >= 0)
    std::snprintf(g_crash_hint, sizeof g_crash_hint,
                  " with its address space limited to %lld MB (ulimit -v): a library may have "
                  "failed for want of memory",
                  mb);
  // The main thread's faults are handled on a stack of their own (one that overflowed has
  // no room left for the handler).
  static char alternate_stack[1 << 16];
  stack_t stack{};
  stack.ss_sp = alternate_stack;
  stack.ss_size = sizeof alternate_stack;
  ::sigaltstack(&stack, nullptr);
  struct sigaction action {};
  action.sa_handler = on_crash;
  action.sa_flags = SA_ONSTACK;
  sigemptyset(&action.sa_mask);
  for (int sig : {SIGABRT, SIGSEGV, SIGBUS, SIGFPE, SIGILL}) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
    if (sig != SIGABRT) continue;  // a sanitizer's own report of a fault says more
#endif
    ::sigaction(sig, &action, nullptr);
  }
}

}  // namespace organfit
