#pragma once
// Output files that appear whole or not at all.
//
// A planning system may pick up any file with a final name, so results are written
// under a temporary name in the same folder and renamed when complete (rename is
// atomic within a file system). An AtomicFile destroyed without commit() removes its
// temporary file: an exception or a signal never leaves a half-written final file.
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

/// Writes `content` to `path` atomically.
void write_file_atomically(const std::filesystem::path& path, const std::string& content);

}  // namespace organfit
