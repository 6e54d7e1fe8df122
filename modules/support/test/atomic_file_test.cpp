#include "organfit/support/atomic_file.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <sstream>

#include "organfit/support/error.h"
#include "organfit/support/output_folder.h"

namespace fs = std::filesystem;

namespace organfit {
namespace {

fs::path fresh_dir(const std::string& name) {
  auto dir = fs::temp_directory_path() / ("organfit_support_" + name + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string read_all(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(AtomicFile, CommitMakesTheFinalFileAndRemovesTheTemporary) {
  const auto dir = fresh_dir("commit");
  write_file_atomically(dir / "out.txt", "hello\n");
  EXPECT_EQ(read_all(dir / "out.txt"), "hello\n");
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 1);
}

TEST(AtomicFile, WithoutCommitNothingIsLeftBehind) {
  const auto dir = fresh_dir("abort");
  {
    AtomicFile f(dir / "half.txt");
    f.stream() << "partial";
    EXPECT_TRUE(fs::exists(f.temp_path()));
  }
  EXPECT_FALSE(fs::exists(dir / "half.txt"));
  EXPECT_TRUE(fs::is_empty(dir));
}

TEST(AtomicFile, UnwritableFolderIsAnInputErrorNamingTheFile) {
  try {
    AtomicFile f("/nonexistent_dir_organfit/x.json");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent_dir_organfit/x.json"), std::string::npos);
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
  }
}

// /dev/full fails every write with ENOSPC, as a full disk does.
TEST(CheckedFileStream, AFailedWriteLeavesTheStreamGoodAndIsReportedAtClose) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  CheckedFileStream out("/dev/full", "/plans/reg.dcm");
  const std::string block(100000, 'x');  // beyond the stream's own buffer
  for (int i = 0; i < 3; ++i)
    out << block;
  EXPECT_TRUE(out.good());  // a writer that asserts on a failed stream runs to its end
  try {
    out.close();
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "/plans/reg.dcm: cannot write: No space left on device");
  }
}

TEST(CheckedFileStream, WritesWhatItIsGiven) {
  const auto dir = fresh_dir("checked");
  {
    CheckedFileStream out(dir / "a.bin", dir / "final.bin");
    for (int i = 0; i < 30000; ++i)
      out << i << '\n';
    out.close();
  }
  std::ostringstream expected;
  for (int i = 0; i < 30000; ++i)
    expected << i << '\n';
  EXPECT_EQ(read_all(dir / "a.bin"), expected.str());
  EXPECT_THROW(CheckedFileStream("/nonexistent_dir_organfit/a.bin", "/x/a.bin"), InputError);
}

TEST(OutputFolder, MessagesNameAStagedFileWhereItWillBe) {
  const auto dir = fresh_dir("final_names");
  const OutputFolder out(dir / "out", {"fit.dcm"});
  const std::string staged = (out.staging() / "fit.dcm").string();
  EXPECT_EQ(out.in_final_names(staged + ": cannot write: No space left on device; " + staged),
            (dir / "out" / "fit.dcm").string() + ": cannot write: No space left on device; " +
                (dir / "out" / "fit.dcm").string());
  EXPECT_EQ(out.in_final_names("points.csv:3: not a number"), "points.csv:3: not a number");
}

TEST(ExitCode, MapsErrorsToTheirCodesAndOthersToInternal) {
  EXPECT_EQ(exit_code_of(InputError("x")), ExitCode::kBadInput);
  EXPECT_EQ(exit_code_of(TargetNotMetError("x")), ExitCode::kTargetNotMet);
  EXPECT_EQ(exit_code_of(std::runtime_error("x")), ExitCode::kInternal);
}

TEST(Echo, ShowsControlBytesAndBytesThatAreNotUtf8AsQuestionMarks) {
  EXPECT_EQ(echo("a\nb\x7f"), "a?b?");
  EXPECT_EQ(echo("caf\xc3\xa9 \xe2\x86\x92"), "caf\xc3\xa9 \xe2\x86\x92");  // kept whole
  EXPECT_EQ(echo("\xff\xfe"), "??");                                        // no lead byte
  EXPECT_EQ(echo("x\xc3"), "x?");                                           // cut short
  EXPECT_EQ(echo("\xe2\x86z"), "??z");                                    // a continuation missing
  EXPECT_EQ(echo("\xc3\xa9\xc3\xa9\xc3\xa9", 2), "\xc3\xa9\xc3\xa9...");  // counted by character
  EXPECT_EQ(echo("abc", 3), "abc");
}

}  // namespace
}  // namespace organfit
