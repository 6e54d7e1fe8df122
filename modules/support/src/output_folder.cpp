#include "organfit/support/output_folder.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>

#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"

namespace fs = std::filesystem;

namespace organfit {
namespace {

/// The absolute, normal form of a path with its existing part's links resolved.
fs::path canonical_form(const fs::path& p) {
  std::error_code ec;
  fs::path c = fs::weakly_canonical(fs::absolute(p, ec), ec);
  if (ec) c = fs::absolute(p).lexically_normal();
  return c;
}

/// True when `ancestor` is `p` or one of its parents (both canonical).
bool is_within(const fs::path& p, const fs::path& ancestor) {
  auto a = ancestor.begin(), b = p.begin();
  for (; a != ancestor.end(); ++a, ++b) {
    if (a->empty()) continue;  // a trailing separator
    if (b == p.end() || *a != *b) return false;
  }
  return true;
}

}  // namespace

void check_output_location(const fs::path& dir, const std::vector<fs::path>& inputs,
                           const std::string& option, OutputKind kind) {
  const bool folder_of_outputs = kind == OutputKind::kFolder;
  const fs::path out = canonical_form(dir);
  auto refuse = [&](const std::string& why) {
    throw InputError(
        fmt::format("{}: {} is {}: choose a separate output folder", dir.string(), option, why));
  };
  const auto depth = std::distance(out.begin(), out.end());
  if (out == out.root_path() || depth <= 1) refuse("the root folder");
  const char* home_env = std::getenv("HOME");
  const fs::path home = home_env && *home_env ? canonical_form(home_env) : fs::path();
  if (folder_of_outputs) {
    if (depth == 2) refuse("a top-level system folder");
    if (!home.empty() && is_within(home, out))
      refuse(out == home ? "the home folder" : "a parent of the home folder");
  } else if (depth == 2 && out != "/tmp" && out != home) {
    refuse("in a top-level system folder");
  }
  for (const auto& input : inputs) {
    std::error_code ec;
    if (input.empty() || !fs::exists(input, ec)) continue;
    const bool is_folder = fs::is_directory(input, ec);
    const fs::path folder = canonical_form(is_folder ? input : input.parent_path());
    if (out == folder) refuse(fmt::format("the folder of input {}", echo(input.string(), 200)));
    if (folder_of_outputs && is_within(folder, out))
      refuse(fmt::format("a parent of the folder of input {}", echo(input.string(), 200)));
    if (is_folder && is_within(out, folder))
      refuse(fmt::format("inside input folder {}", echo(input.string(), 200)));
  }
}

CreatedFolders::CreatedFolders(const fs::path& dir, bool with_contents)
    : with_contents_(with_contents) {
  std::vector<fs::path> missing;
  std::error_code ec;
  for (fs::path p = fs::absolute(dir).lexically_normal(); !p.empty() && !fs::exists(p, ec);
       p = p.parent_path()) {
    missing.push_back(p);
    if (p == p.parent_path()) break;
  }
  for (auto it = missing.rbegin(); it != missing.rend(); ++it) {
    if (!fs::create_directory(*it, ec) && ec) {
      const std::string why = ec.message();
      for (auto made = created_.rbegin(); made != created_.rend(); ++made)
        fs::remove(*made, ec);  // those made so far go again
      throw InputError(dir.string() + ": cannot create the output folder: " + why);
    }
    created_.push_back(*it);
    const bool whole = with_contents && std::next(it) == missing.rend();  // `dir` itself
    partial_.push_back(std::make_unique<PartialPath>(*it, !whole));
  }
  if (!fs::is_directory(dir, ec)) throw InputError(dir.string() + ": exists and is not a folder");
}

CreatedFolders::~CreatedFolders() {
  std::error_code ec;
  for (auto it = created_.rbegin(); it != created_.rend(); ++it) {
    if (with_contents_ && it == created_.rbegin())  // the deepest made: `dir` itself
      fs::remove_all(*it, ec);
    else if (fs::is_empty(*it, ec))
      fs::remove(*it, ec);
  }
}

void CreatedFolders::keep() {
  created_.clear();
  partial_.clear();
}

namespace {
/// The outputs the run.json in `dir` lists (an earlier organfit run's own), with the data
/// files beside a listed .mhd or .nhdr, and run.json itself; empty when there is none.
std::set<std::string> earlier_outputs(const fs::path& dir) {
  std::set<std::string> names;
  std::ifstream earlier(dir / "run.json");
  if (!earlier) return names;
  const nlohmann::json run = nlohmann::json::parse(earlier, nullptr, false);
  if (!run.is_object() || !run.contains("organfit_version") || !run.contains("outputs") ||
      !run["outputs"].is_array())
    return names;
  for (const auto& o : run["outputs"])
    if (o.is_string()) {
      std::string name = o.get<std::string>();
      if (!name.empty() && name.back() == '/') name.pop_back();
      // Plain, visible names only: an output is an entry of the folder, never a path out of
      // it, nor a run's hidden staging folder.
      if (name.empty() || name[0] == '.' || name.find('/') != std::string::npos) continue;
      names.insert(name);
      const fs::path p(name);
      if (p.extension() == ".mhd" || p.extension() == ".nhdr")
        for (const char* ext : {".raw", ".zraw", ".raw.gz"})
          names.insert(p.stem().string() + ext);
    }
  names.insert("run.json");
  return names;
}

/// An exclusive lock on the folder while it lives (flock on the folder itself): two runs
/// into one --out commit one after the other, never interleaved.
class FolderLock {
 public:
  explicit FolderLock(const fs::path& dir)
      : fd_(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)) {
    if (fd_ >= 0)
      while (::flock(fd_, LOCK_EX) != 0 && errno == EINTR) {
      }
  }
  ~FolderLock() {
    if (fd_ >= 0) ::close(fd_);  // releases the lock
  }
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;

 private:
  int fd_;
};
}  // namespace

OutputFolder::OutputFolder(const fs::path& dir, const std::set<std::string>& names_to_write,
                           const std::string& option)
    : dir_(dir), option_(option), created_(dir) {
  // An earlier run's own outputs, which this one may replace.
  earlier_outputs_ = earlier_outputs(dir_);
  for (std::string name : names_to_write) {
    if (!name.empty() && name.back() == '/') name.pop_back();
    check_replaceable(name);
  }
  staging_ = dir_ / fmt::format(".organfit-run-{}", static_cast<long>(::getpid()));
  partial_staging_ = std::make_unique<PartialPath>(staging_);
  std::error_code ec;
  fs::remove_all(staging_, ec);  // a stale one of a killed run with this process id
  if (!fs::create_directory(staging_, ec))
    throw InputError(dir_.string() + ": cannot write in the output folder: " + ec.message());
}

std::string OutputFolder::in_final_names(const std::string& text) const {
  const std::string from = staging_.string() + "/", to = dir_.string() + "/";
  std::string out = text;
  for (size_t at = 0; (at = out.find(from, at)) != std::string::npos; at += to.size())
    out.replace(at, from.size(), to);
  return out;
}

void OutputFolder::check_replaceable(const std::string& name) const {
  std::error_code ec;
  const fs::path target = dir_ / name;
  if (!fs::exists(fs::symlink_status(target, ec))) return;
  if (!earlier_outputs_.count(name))
    throw InputError(fmt::format(
        "{}: exists and was not written by organfit (no earlier run.json there lists it): "
        "move it, or choose another {}",
        target.string(), option_));
}

OutputFolder::~OutputFolder() {
  if (committed_) return;
  std::error_code ec;
  if (!staging_.empty()) fs::remove_all(staging_, ec);
}

void OutputFolder::commit() {
  throw_if_interrupted();  // the last moment a run can still stop with nothing written
  const ScopedCommit committing;
  // What the folder holds now, under the lock: another run may have committed into it
  // since this one started.
  const FolderLock lock(dir_);
  earlier_outputs_ = earlier_outputs(dir_);
  std::error_code ec;
  std::vector<fs::path> entries;
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(staging_, ec))
    entries.push_back(e.path()), names.insert(e.path().filename().string());
  if (ec) throw InputError(staging_.string() + ": cannot list the staged outputs: " + ec.message());
  for (const auto& e : entries)
    check_replaceable(e.filename().string());
  // A run (it writes a run.json) replaces the earlier run whole: that run's outputs this
  // one does not write go first (a report, a field or a REG object of another fit must not
  // lie beside this one's), while its old run.json still lists them. What writes no
  // run.json (a `dicom pull`) only adds its own entries.
  std::vector<std::string> removed;
  const bool replaces_the_run = names.count("run.json") > 0;
  for (const std::string& name : earlier_outputs_)
    if (replaces_the_run && !names.count(name) && fs::exists(fs::symlink_status(dir_ / name, ec))) {
      fs::remove_all(dir_ / name, ec);
      if (ec)
        throw InputError((dir_ / name).string() +
                         ": cannot remove (an earlier run's "
                         "output this run does not replace): " +
                         ec.message());
      removed.push_back(name);
    }
  if (!removed.empty())
    spdlog::info(
        "{}: {} output(s) of the earlier run there that this run does not write were "
        "removed ({})",
        dir_.string(), removed.size(), fmt::join(removed, ", "));
  // run.json last: while it is absent or old, no reader takes the folder for a finished run.
  std::stable_partition(entries.begin(), entries.end(),
                        [](const fs::path& p) { return p.filename() != "run.json"; });
  for (const auto& e : entries) {
    const fs::path target = dir_ / e.filename();
    if (fs::is_directory(e, ec) && fs::exists(target, ec)) {
      // A folder is replaced whole: the old one set aside first, removed once the new is in.
      const fs::path old = staging_.string() + ".old-" + e.filename().string();
      fs::rename(target, old, ec);
      if (ec) throw InputError(target.string() + ": cannot replace: " + ec.message());
      fs::rename(e, target, ec);
      if (ec) throw InputError(target.string() + ": cannot move into place: " + ec.message());
      fs::remove_all(old, ec);
      continue;
    }
    fs::rename(e, target, ec);
    if (ec) throw InputError(target.string() + ": cannot move into place: " + ec.message());
  }
  fs::remove_all(staging_, ec);
  created_.keep();
  committed_ = true;
  partial_staging_.reset();
}

}  // namespace organfit
