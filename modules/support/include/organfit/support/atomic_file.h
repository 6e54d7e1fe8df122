#pragma once
// Output files that appear whole or not at all.
//
// A planning system may pick up any file with a final name, so results are written
// under a temporary name in the same folder and renamed when complete (rename is
// atomic within a file system). An AtomicFile destroyed without commit() removes its
// temporary file: an exception or a signal never leaves a half-written final file.
//
// A write that fails (a full disk, an I/O error) is an error naming the final file and
// the reason (exit 2, as an output folder that cannot be written). Not every library
// reports one: ITK's MetaImage writer prints it and carries on, GDCM asserts (aborts) on a
// stream that failed. So a file system a write left with no space free to users is taken
// as having cut that write short (check_room_left), whichever library wrote it, and GDCM
// writes to a CheckedFileStream, which never fails under it.
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

namespace organfit {

class PartialPath;

class AtomicFile {
 public:
  /// Opens `<dir>/.<name>.tmp-<pid>` for writing; throws InputError naming the file
  /// when the folder cannot be written.
  explicit AtomicFile(std::filesystem::path final_path, bool binary = false);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::ostream& stream() { return out_; }
  const std::filesystem::path& temp_path() const { return temp_path_; }
  const std::filesystem::path& final_path() const { return final_path_; }

  /// Flushes, checks the stream and renames to the final name. Throws on failure.
  void commit();

 private:
  std::filesystem::path final_path_;
  std::filesystem::path temp_path_;
  std::ofstream out_;
  std::unique_ptr<PartialPath> partial_;
  bool committed_ = false;
};

/// The same for writers that take a file name (ITK, VTK, GDCM): they write to path(),
/// the final name inside a temporary folder beside it (formats are chosen by extension,
/// and a .mhd or .nhdr names its data file by its own name); commit() renames what was
/// written into place. Destroyed uncommitted, the temporary folder is removed. path()
/// may also be a folder written file by file (a DICOM series).
class TempPath {
 public:
  explicit TempPath(std::filesystem::path final_path);
  ~TempPath();
  TempPath(const TempPath&) = delete;
  TempPath& operator=(const TempPath&) = delete;

  const std::filesystem::path& path() const { return temp_path_; }
  /// Renames into place; throws InputError "FILE: cannot move into place: ..." on failure.
  void commit();

 private:
  std::filesystem::path final_path_, temp_dir_, temp_path_;
  std::unique_ptr<PartialPath> partial_;
  bool committed_ = false;
};

/// An output stream on a file that stays good when a write fails: the first failure's
/// reason (errno) is kept, the rest of the output dropped, and close() reports it. For
/// writers that abort on a failed stream: they run to their end, and the file is judged.
class CheckedFileStream : public std::ostream {
 public:
  /// Opens (creates or truncates) `path`; throws InputError naming `final_path` when it
  /// cannot be.
  CheckedFileStream(const std::filesystem::path& path, const std::filesystem::path& final_path);
  ~CheckedFileStream() override;
  CheckedFileStream(const CheckedFileStream&) = delete;
  CheckedFileStream& operator=(const CheckedFileStream&) = delete;

  /// Flushes and closes; throws InputError "FINAL: cannot write: REASON" when any write
  /// (or the close) failed, or when the file system was left full (check_room_left).
  void close();

 private:
  class Buffer;
  std::unique_ptr<Buffer> buffer_;
  std::filesystem::path path_, final_path_;
};

/// Throws InputError "FINAL: cannot write: no space left on its file system" when the file
/// system holding `written` has no block free to users (a write there may have been cut
/// short without its writer saying so). File systems that state no size are not judged.
void check_room_left(const std::filesystem::path& written, const std::filesystem::path& final_path);

/// Writes `content` to `path` atomically.
void write_file_atomically(const std::filesystem::path& path, const std::string& content);

}  // namespace organfit
