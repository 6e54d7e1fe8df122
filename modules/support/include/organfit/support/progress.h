#pragma once
// Progress of a long stage on stderr: a redrawn bar when stderr is a terminal, plain
// periodic lines ("fit: 40% (400/1000), 1.2 s") when it is not (logs, CI), nothing
// when quiet. Updates are cheap to call every step: output is throttled by time. A
// heartbeat thread redraws the last state when no update came for an interval, so a
// long step between two updates (a global fit of a million particles) still shows its
// clock running.
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <string>
#include <thread>

namespace organfit {

class Progress {
 public:
  /// `total` is the number of units of work (0 = unknown: shows a count only).
  Progress(std::string stage, long long total);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  /// Reports `done` units finished, with an optional short status ("residual 0.4 mm").
  void update(long long done, const std::string& status = {});
  /// Ends the display (also done by the destructor).
  void finish();

  /// Global switch: false silences every Progress (used by --quiet).
  static void set_enabled(bool enabled);
  /// Forces the plain-line mode even on a terminal (tests).
  static void set_force_plain(bool plain);
  /// Seconds between plain lines (default 5; tests use 0, which also turns the heartbeat
  /// off: every update draws).
  static void set_plain_interval_s(double seconds);

 private:
  void draw(long long done, const std::string& status, bool final_line);
  void beat();  ///< the heartbeat thread's loop
  std::string stage_;
  long long total_;
  long long last_done_ = 0;
  std::string last_status_;
  std::chrono::duration<double> interval_;
  std::chrono::steady_clock::time_point start_, last_draw_;
  bool tty_ = false;
  bool finished_ = false;
  bool drawn_ = false;
  std::mutex mutex_;  ///< the state above, shared with the heartbeat
  std::condition_variable wake_;
  std::thread heartbeat_;
};

}  // namespace organfit
