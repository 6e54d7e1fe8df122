#include "organfit/support/atomic_file.h"

#include <fmt/format.h>
#include <unistd.h>

#include <vector>

#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"

namespace organfit {

AtomicFile::AtomicFile(std::filesystem::path final_path, bool binary)
    : final_path_(std::move(final_path)) {
  const auto dir =
      final_path_.has_parent_path() ? final_path_.parent_path() : std::filesystem::path(".");
  temp_path_ =
      dir / fmt::format(".{}.tmp-{}", final_path_.filename().string(), static_cast<long>(getpid()));
  partial_ = std::make_unique<PartialPath>(temp_path_);
  out_.open(temp_path_, binary ? std::ios::out | std::ios::binary | std::ios::trunc
                               : std::ios::out | std::ios::trunc);
  if (!out_) {
    throw InputError(fmt::format("{}: cannot write here (folder missing or not writable)",
                                 final_path_.string()));
  }
}

AtomicFile::~AtomicFile() {
  if (!committed_) {
    out_.close();
    std::error_code ec;
    std::filesystem::remove(temp_path_, ec);
  }
}

void AtomicFile::commit() {
  out_.flush();
  const bool ok = static_cast<bool>(out_);
  out_.close();
  if (!ok) throw Error(ExitCode::kInternal, fmt::format("{}: write failed", final_path_.string()));
  std::error_code ec;
  std::filesystem::rename(temp_path_, final_path_, ec);
  if (ec) {
    throw Error(ExitCode::kInternal, fmt::format("{}: cannot rename into place: {}",
                                                 final_path_.string(), ec.message()));
  }
  committed_ = true;
}

TempPath::TempPath(std::filesystem::path final_path)
    : final_path_(std::move(final_path)),
      temp_dir_(final_path_.parent_path() / fmt::format(".tmp-{}-{}", static_cast<long>(getpid()),
                                                        final_path_.filename().string())),
      temp_path_(temp_dir_ / final_path_.filename()) {
  partial_ = std::make_unique<PartialPath>(temp_dir_);
  std::error_code ec;
  std::filesystem::remove_all(temp_dir_, ec);
  std::filesystem::create_directory(temp_dir_, ec);  // a writer reports a folder it cannot use
}

TempPath::~TempPath() {
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove_all(temp_dir_, ec);
  }
}

void TempPath::commit() {
  std::error_code ec;
  // The file and whatever its writer put beside it (the data file of a .mhd or .nhdr,
  // which its header names by the final name), each renamed into place.
  std::vector<std::filesystem::path> entries;
  for (const auto& e : std::filesystem::directory_iterator(temp_dir_, ec))
    entries.push_back(e.path());
  if (ec || entries.empty())
    throw InputError(final_path_.string() + ": cannot move into place: nothing was written");
  for (const auto& e : entries) {
    std::filesystem::rename(e, final_path_.parent_path() / e.filename(), ec);
    if (ec) throw InputError(final_path_.string() + ": cannot move into place: " + ec.message());
  }
  std::filesystem::remove_all(temp_dir_, ec);
  committed_ = true;
}

void write_file_atomically(const std::filesystem::path& path, const std::string& content) {
  AtomicFile file(path);
  file.stream() << content;
  file.commit();
}

}  // namespace organfit
