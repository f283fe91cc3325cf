// Progress: what long work prints in each mode, captured through a temporary FILE*.
#include "core/progress.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

namespace facedyn {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
using ::testing::StartsWith;

// A std::tmpfile whose whole contents can be read back.
class CapturedFile {
 public:
  CapturedFile() : file_(std::tmpfile()) {}
  ~CapturedFile() {
    if (file_) std::fclose(file_);
  }
  std::FILE* get() const { return file_; }
  std::string Contents() const {
    std::fflush(file_);
    std::rewind(file_);
    std::string text;
    char buffer[4096];
    size_t n;
    while ((n = std::fread(buffer, 1, sizeof(buffer), file_)) > 0) text.append(buffer, n);
    return text;
  }

 private:
  std::FILE* file_;
};

size_t CountOf(const std::string& text, char c) { return std::count(text.begin(), text.end(), c); }

TEST(ProgressLines, FinalLineHasLabelCountsAndStatus) {
  CapturedFile out;
  ASSERT_NE(out.get(), nullptr);
  {
    Progress progress("export", 10, ProgressMode::kLines, out.get(), /*line_interval_s=*/3600.0);
    EXPECT_EQ(progress.mode(), ProgressMode::kLines);
    for (int i = 0; i < 10; ++i) progress.Advance();
    EXPECT_EQ(out.Contents(), "");  // the interval has not passed: nothing yet
    progress.Finish("12 files");
  }
  const std::string text = out.Contents();
  EXPECT_EQ(CountOf(text, '\n'), 1u) << text;
  EXPECT_THAT(text, StartsWith("export: 10/10 100% in "));
  EXPECT_THAT(text, HasSubstr("s  12 files\n"));
  EXPECT_THAT(text, Not(HasSubstr("\r")));
  EXPECT_THAT(text, Not(HasSubstr("[")));
}

TEST(ProgressLines, ZeroIntervalPrintsEveryUpdate) {
  CapturedFile out;
  Progress progress("fit", 4, ProgressMode::kLines, out.get(), /*line_interval_s=*/0.0);
  progress.Advance();
  progress.Update(3, "loss 0.5");
  progress.Finish();
  const std::string text = out.Contents();
  EXPECT_EQ(CountOf(text, '\n'), 3u) << text;
  EXPECT_THAT(text, HasSubstr("fit: 1/4  25% eta "));
  EXPECT_THAT(text, HasSubstr("fit: 3/4  75% eta "));
  EXPECT_THAT(text, HasSubstr("  loss 0.5\n"));
  EXPECT_THAT(text, HasSubstr("fit: 4/4 100% in "));
}

TEST(ProgressLines, UnknownTotalShowsTheCount) {
  CapturedFile out;
  {
    Progress progress("frames", 0, ProgressMode::kLines, out.get(), 3600.0);
    progress.Advance(5);
    progress.Advance(2);
  }  // the destructor finishes the line
  EXPECT_THAT(out.Contents(), StartsWith("frames: 7 in "));
  EXPECT_EQ(CountOf(out.Contents(), '\n'), 1u);
}

TEST(ProgressFinish, PrintsOnce) {
  CapturedFile out;
  {
    Progress progress("once", 2, ProgressMode::kLines, out.get(), 3600.0);
    progress.Finish("first");
    progress.Finish("second");
  }
  const std::string text = out.Contents();
  EXPECT_EQ(CountOf(text, '\n'), 1u) << text;
  EXPECT_THAT(text, HasSubstr("first"));
  EXPECT_THAT(text, Not(HasSubstr("second")));
}

TEST(ProgressSilent, PrintsNothing) {
  CapturedFile out;
  {
    Progress progress("quiet", 100, ProgressMode::kSilent, out.get(), 0.0);
    for (int i = 0; i < 100; ++i) progress.Advance();
    progress.Update(50, "status");
    progress.Finish("done");
  }
  EXPECT_EQ(out.Contents(), "");
}

TEST(ProgressBar, RedrawsOneLineWithABar) {
  CapturedFile out;
  {
    Progress progress("reconstruct", 4, ProgressMode::kBar, out.get());
    progress.Advance(2);
    progress.Finish();
  }
  const std::string text = out.Contents();
  EXPECT_THAT(text, StartsWith("\r"));
  EXPECT_THAT(text, HasSubstr("reconstruct ["));
  EXPECT_THAT(text, HasSubstr("[" + std::string(30, '=') + "] 4/4 100% in "));
  EXPECT_EQ(CountOf(text, '\n'), 1u) << text;
  EXPECT_EQ(text.back(), '\n');
}

TEST(ProgressBar, PartialBar) {
  CapturedFile out;
  Progress progress("half", 10, ProgressMode::kBar, out.get());
  std::this_thread::sleep_for(std::chrono::milliseconds(120));  // bars redraw at most at 10 Hz
  progress.Advance(5);
  const std::string text = out.Contents();
  EXPECT_THAT(text, HasSubstr("half [" + std::string(15, '=') + ">" + std::string(14, ' ') +
                              "] 5/10  50%"));
  EXPECT_EQ(CountOf(text, '\n'), 0u);  // the line stays open until Finish
  progress.Finish();
}

TEST(ProgressAuto, FileIsNotATerminalSoLines) {
  CapturedFile out;
  Progress progress("auto", 1, ProgressMode::kAuto, out.get());
  EXPECT_EQ(progress.mode(), ProgressMode::kLines);
  progress.Finish();
}

TEST(ProgressAuto, DefaultModeApplies) {
  CapturedFile out;
  SetDefaultProgressMode(ProgressMode::kSilent);
  {
    Progress progress("auto", 3, ProgressMode::kAuto, out.get(), 0.0);
    EXPECT_EQ(progress.mode(), ProgressMode::kSilent);
    progress.Advance(3);
  }
  SetDefaultProgressMode(ProgressMode::kAuto);
  EXPECT_EQ(out.Contents(), "");
}

TEST(ProgressAdvance, ConcurrentWorkersAreCounted) {
  CapturedFile out;
  {
    Progress progress("parallel", 0, ProgressMode::kLines, out.get(), 3600.0);
    std::vector<std::thread> workers;
    for (int t = 0; t < 4; ++t) {
      workers.emplace_back([&progress] {
        for (int i = 0; i < 2500; ++i) progress.Advance();
      });
    }
    for (auto& worker : workers) worker.join();
  }
  EXPECT_THAT(out.Contents(), StartsWith("parallel: 10000 in "));
}

}  // namespace
}  // namespace facedyn
