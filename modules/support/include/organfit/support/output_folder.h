#pragma once
// Where organfit may write, and writing a run's outputs as a whole or not at all.
//
// A planning system trusts what lands in an output folder, and a mistyped --out must not
// spill files among a CT's slices or into a system folder. So: outputs go to a folder
// that is no input's folder nor a parent of one, never `/`, a top-level folder or the
// home folder; a run writes into a hidden staging folder inside --out and moves its
// outputs into place only when it has completed. A refused, failed or interrupted run
// leaves --out as it found it (a folder it created is removed again).
#include <filesystem>
#include <memory>
#include <set>
#include <string>
#include <vector>

namespace organfit {

class PartialPath;

/// What is written to the place checked: a run's folder of outputs, or one named file.
enum class OutputKind { kFolder, kFile };

/// Refuses `dir` as a place for outputs, with InputError "DIR: <option> is ...".
/// A folder of outputs (kFolder) may not be `/`, a folder directly under `/` (/tmp,
/// /usr, /home, ...), the home folder or one above it, the folder of an input (a file's
/// folder, or a folder input itself), a parent of one, or a folder inside a folder input
/// (a DICOM folder is read whole). The folder of one named file (kFile) may not be `/`, a
/// top-level system folder other than /tmp and the home folder, an input's folder or a
/// folder inside a folder input. `inputs` are files or folders; missing ones are ignored.
void check_output_location(const std::filesystem::path& dir,
                           const std::vector<std::filesystem::path>& inputs,
                           const std::string& option, OutputKind kind = OutputKind::kFolder);

/// The missing folders of a path, created and removed again unless keep() is called (also
/// by the watchdog on a stop): an output file's folders vanish with a failed command.
/// The folders are removed when still empty; with `with_contents`, `dir` itself goes with
/// all it holds (a benchmark writing as it runs leaves no partial folder). Folders that
/// existed are left as they are.
class CreatedFolders {
 public:
  /// Creates `dir` and its missing parents; InputError naming it when it cannot.
  explicit CreatedFolders(const std::filesystem::path& dir, bool with_contents = false);
  ~CreatedFolders();
  CreatedFolders(const CreatedFolders&) = delete;
  CreatedFolders& operator=(const CreatedFolders&) = delete;
  void keep();

 private:
  std::vector<std::filesystem::path> created_;  // deepest last
  std::vector<std::unique_ptr<PartialPath>> partial_;
  bool with_contents_ = false;
};

/// One run's output folder. The run writes under staging(); commit() moves each entry of
/// it into the output folder. An entry may replace one already there only when an
/// earlier organfit run wrote it: it is listed in that run's run.json "outputs" (with a
/// detached data file beside a listed .mhd or .nhdr); anything else is refused naming the
/// file, before work starts (names_to_write) and again at commit. A run that writes a
/// run.json replaces the earlier run whole: that run's outputs this one does not write are
/// removed at commit (a report or a field of another fit must not lie beside this run's);
/// one that writes none (`dicom pull`) only adds its entries. Other files are left alone.
/// Commits into one folder hold a lock on it (flock): two runs started together end as the
/// later one's outputs alone, never a mix.
class OutputFolder {
 public:
  /// `names_to_write`: the entries the run expects to write (a folder ends in '/').
  OutputFolder(const std::filesystem::path& dir, const std::set<std::string>& names_to_write,
               const std::string& option = "--out");
  ~OutputFolder();
  OutputFolder(const OutputFolder&) = delete;
  OutputFolder& operator=(const OutputFolder&) = delete;

  const std::filesystem::path& staging() const { return staging_; }
  /// `text` with every path in the staging folder named as the output it stands for
  /// (`OUT/.organfit-run-PID/fit.dcm` as `OUT/fit.dcm`): for messages.
  std::string in_final_names(const std::string& text) const;
  const std::filesystem::path& dir() const { return dir_; }
  /// Moves the staged entries into place (signals are not looked at: it takes
  /// milliseconds, and a run that got this far is whole).
  void commit();

 private:
  void check_replaceable(const std::string& name) const;
  std::filesystem::path dir_, staging_;
  std::string option_;
  std::set<std::string> earlier_outputs_;
  CreatedFolders created_;
  std::unique_ptr<PartialPath> partial_staging_;
  bool committed_ = false;
};

}  // namespace organfit
