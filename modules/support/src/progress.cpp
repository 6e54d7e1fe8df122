#include "organfit/support/progress.h"

#include <fmt/format.h>
#include <unistd.h>

namespace organfit {
namespace {
bool g_enabled = true;
bool g_force_plain = false;
// Terminals are redrawn often; logs get a line every few seconds at most.
constexpr double kTtyIntervalS = 0.1;
double g_plain_interval_s = 5.0;
}  // namespace

void Progress::set_enabled(bool enabled) {
  g_enabled = enabled;
}
void Progress::set_force_plain(bool plain) {
  g_force_plain = plain;
}
void Progress::set_plain_interval_s(double seconds) {
  g_plain_interval_s = seconds;
}

Progress::Progress(std::string stage, long long total)
    : stage_(std::move(stage)),
      total_(total),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_),
      tty_(!g_force_plain && isatty(fileno(stderr))) {
  interval_ = std::chrono::duration<double>(tty_ ? kTtyIntervalS : g_plain_interval_s);
  if (g_enabled && interval_.count() > 0) heartbeat_ = std::thread([this] { beat(); });
}

Progress::~Progress() {
  finish();
}

void Progress::beat() {
  std::unique_lock<std::mutex> lock(mutex_);
  while (!finished_) {
    const auto due =
        last_draw_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(interval_);
    wake_.wait_until(lock, due);
    const auto now = std::chrono::steady_clock::now();
    if (finished_ || now - last_draw_ < interval_) continue;  // an update drew meanwhile
    last_draw_ = now;
    draw(last_done_, last_status_, false);
  }
}

void Progress::update(long long done, const std::string& status) {
  std::lock_guard<std::mutex> lock(mutex_);
  last_done_ = done;
  last_status_ = status;
  if (!g_enabled || finished_) return;
  const auto now = std::chrono::steady_clock::now();
  if (now - last_draw_ < interval_) return;
  last_draw_ = now;
  draw(done, status, false);
}

void Progress::finish() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (finished_) return;
    finished_ = true;
    // Only close a display that was shown: a quick stage prints nothing.
    if (g_enabled && drawn_) draw(last_done_, "done", true);
  }
  wake_.notify_all();
  if (heartbeat_.joinable()) heartbeat_.join();
}

void Progress::draw(long long done, const std::string& status, bool final_line) {
  drawn_ = true;
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  std::string line;
  if (total_ > 0) {
    const double frac = std::min(1.0, static_cast<double>(done) / static_cast<double>(total_));
    if (tty_) {
      constexpr int kWidth = 30;
      const int filled = static_cast<int>(frac * kWidth);
      line = fmt::format("{} [{}{}] {:3.0f}% {:.1f} s", stage_, std::string(filled, '#'),
                         std::string(kWidth - filled, '.'), 100 * frac, elapsed);
    } else {
      line =
          fmt::format("{}: {:.0f}% ({}/{}), {:.1f} s", stage_, 100 * frac, done, total_, elapsed);
    }
  } else {
    line = fmt::format("{}: {} done, {:.1f} s", stage_, done, elapsed);
  }
  if (!status.empty()) line += ", " + status;
  if (tty_) {
    std::fprintf(stderr, "\r\033[K%s%s", line.c_str(), final_line ? "\n" : "");
  } else {
    std::fprintf(stderr, "%s\n", line.c_str());
  }
  std::fflush(stderr);
}

}  // namespace organfit
