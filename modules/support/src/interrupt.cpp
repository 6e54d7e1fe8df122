#include "organfit/support/interrupt.h"

#include <fcntl.h>
#include <pthread.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <thread>

#include "organfit/support/error.h"

namespace organfit {
namespace {

enum Stop : int { kRunning = 0, kSignalled = 1, kOutOfTime = 2 };
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

std::string stop_message() {
  if (g_stop.load() == kOutOfTime) {
    char text[256];
    std::snprintf(text, sizeof text,
                  "the run took longer than %s (%g s) and was stopped: nothing was written",
                  g_budget_name, g_budget_s);
    return text;
  }
  return "interrupted (SIGINT or SIGTERM): nothing was written";
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
      stop_at = now_s() + kStopGrace;
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
        std::error_code ec;
        const std::filesystem::path& path = it->second.path;
        if (it->second.only_if_empty) {
          if (std::filesystem::is_empty(path, ec)) std::filesystem::remove(path, ec);
          continue;
        }
        // Moved aside first, then removed: the run's thread may still be writing into it
        // (a file made between remove_all's listing and its last rmdir left the folder
        // behind), and a path it opens after the move no longer leads there.
        // Named for this process: one left by an earlier crash would make the move fail.
        std::filesystem::path aside = path;
        aside += ".removing-" + std::to_string(::getpid());
        std::filesystem::rename(path, aside, ec);
        std::filesystem::remove_all(ec ? path : aside, ec);
      }
      const std::string line = "organfit: error: " + stop_message() + "\n";
      (void)!::write(2, line.data(), line.size());
      ::_exit(g_stop.load() == kOutOfTime ? static_cast<int>(ExitCode::kTargetNotMet)
                                          : static_cast<int>(ExitCode::kInterrupted));
    }
  }
}

}  // namespace

void install_abort_guard();

void install_interrupt_handlers() {
  static bool installed = false;
  if (installed) return;
  installed = true;
  install_abort_guard();
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
  throw Error(g_stop.load() == kOutOfTime ? ExitCode::kTargetNotMet : ExitCode::kInterrupted,
              stop_message());
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

void on_abort(int) {
  // The watchdog is removing what this thread was writing (GDCM asserts that the file it
  // opens is open): it ends the process itself in a moment, with the interrupt's message.
  if (g_ending.load())
    for (;;)
      ::pause();
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
