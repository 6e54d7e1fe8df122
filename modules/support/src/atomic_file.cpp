#include "organfit/support/atomic_file.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
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

namespace {
std::string cannot_write(const std::filesystem::path& final_path, int error) {
  return fmt::format("{}: cannot write: {}", final_path.string(),
                     error ? std::strerror(error) : "the write failed");
}
}  // namespace

void check_room_left(const std::filesystem::path& written,
                     const std::filesystem::path& final_path) {
  struct statvfs fs {};
  if (::statvfs(written.c_str(), &fs) != 0 || fs.f_blocks == 0) return;
  if (fs.f_bavail == 0)
    throw InputError(final_path.string() + ": cannot write: no space left on its file system");
}

void AtomicFile::commit() {
  // errno from here is the flush's or the close's: a stream that failed earlier makes no
  // call, and its reason is found by the room left, or is not known.
  errno = 0;
  out_.flush();
  out_.close();
  const int error = errno;
  check_room_left(temp_path_, final_path_);
  if (!out_) throw InputError(cannot_write(final_path_, error));
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
  check_room_left(temp_dir_, final_path_);
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

/// Writes through a buffer to a file descriptor; a failed write(2) is kept (its errno) and
/// everything after it dropped, the stream left good.
class CheckedFileStream::Buffer : public std::streambuf {
 public:
  explicit Buffer(int fd) : fd_(fd) { setp(data_, data_ + sizeof data_); }
  int close() {
    sync();
    if (fd_ >= 0 && ::close(fd_) != 0 && error_ == 0) error_ = errno;
    fd_ = -1;
    return error_;
  }

 protected:
  int_type overflow(int_type c) override {
    drain();
    if (!traits_type::eq_int_type(c, traits_type::eof())) {
      *pptr() = traits_type::to_char_type(c);
      pbump(1);
    }
    return traits_type::not_eof(c);
  }
  int sync() override {
    drain();
    return 0;
  }

 private:
  void drain() {
    const char* p = pbase();
    size_t left = static_cast<size_t>(pptr() - pbase());
    while (left > 0 && error_ == 0 && fd_ >= 0) {
      const ssize_t n = ::write(fd_, p, left);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        error_ = n < 0 ? errno : EIO;
        break;
      }
      p += n, left -= static_cast<size_t>(n);
    }
    setp(data_, data_ + sizeof data_);
  }
  int fd_;
  int error_ = 0;
  char data_[1 << 16];
};

CheckedFileStream::CheckedFileStream(const std::filesystem::path& path,
                                     const std::filesystem::path& final_path)
    : std::ostream(nullptr), path_(path), final_path_(final_path) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0)
    throw InputError(
        fmt::format("{}: cannot write here: {}", final_path.string(), std::strerror(errno)));
  buffer_ = std::make_unique<Buffer>(fd);
  rdbuf(buffer_.get());
}

CheckedFileStream::~CheckedFileStream() {
  if (buffer_) buffer_->close();
}

void CheckedFileStream::close() {
  const int error = buffer_->close();
  if (error) throw InputError(cannot_write(final_path_, error));
  check_room_left(path_, final_path_);
}

void write_file_atomically(const std::filesystem::path& path, const std::string& content) {
  AtomicFile file(path);
  file.stream() << content;
  file.commit();
}

}  // namespace organfit
