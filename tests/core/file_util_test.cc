// File helpers: reads that say what went wrong, atomic writes, directories, paths; and the
// JSON writer built on them.
#include "core/file_util.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <string>

#include "core/json_io.h"
#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::ReadBytes;
using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

TEST(ReadFileToString, ReadsBinaryContents) {
  TempDir dir;
  const std::string bytes("a\0b\r\n\xff", 6);
  WriteBytes(dir.Join("data.bin"), bytes);
  const auto read = ReadFileToString(dir.Join("data.bin"));
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(*read, bytes);
}

TEST(ReadFileToString, MissingFileAndDirectory) {
  TempDir dir;
  const auto missing = ReadFileToString(dir.Join("absent.txt"));
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(missing.status().message(), dir.Join("absent.txt") + ": no such file");
  const auto directory = ReadFileToString(dir.path());
  ASSERT_FALSE(directory.ok());
  EXPECT_EQ(directory.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(directory.status().message(), HasSubstr("is a directory"));
}

TEST(WriteFileAtomic, WritesReplacesAndLeavesNoTemporary) {
  TempDir dir;
  const std::string path = dir.Join("out.txt");
  ASSERT_TRUE(WriteFileAtomic(path, "first version, longer\n").ok());
  ASSERT_TRUE(WriteFileAtomic(path, "second\n").ok());
  EXPECT_EQ(ReadBytes(path), "second\n");
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
  ASSERT_TRUE(WriteFileAtomic(path, "").ok());
  EXPECT_EQ(ReadBytes(path), "");
}

TEST(WriteFileAtomic, FailureKeepsTheOldFile) {
  TempDir dir;
  const std::string path = dir.Join("out.txt");
  ASSERT_TRUE(WriteFileAtomic(path, "old\n").ok());
  // A directory where the temporary file must go makes the write fail before the rename.
  std::filesystem::create_directory(path + ".tmp");
  const Status status = WriteFileAtomic(path, "new\n");
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.code(), StatusCode::kUnavailable);
  EXPECT_THAT(status.message(), HasSubstr(path + ".tmp"));
  EXPECT_EQ(ReadBytes(path), "old\n");
}

TEST(WriteFileAtomic, MissingFolder) {
  TempDir dir;
  const Status status = WriteFileAtomic(dir.Join("no/such/folder/out.txt"), "x");
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("no/such/folder/out.txt"));
}

TEST(MakeDirectories, CreatesParentsAndAcceptsExisting) {
  TempDir dir;
  const std::string nested = dir.Join("a/b/c");
  ASSERT_TRUE(MakeDirectories(nested).ok());
  EXPECT_TRUE(std::filesystem::is_directory(nested));
  EXPECT_TRUE(MakeDirectories(nested).ok());
}

TEST(MakeDirectories, RefusesAFile) {
  TempDir dir;
  WriteBytes(dir.Join("file"), "x");
  const Status status = MakeDirectories(dir.Join("file"));
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr(dir.Join("file")));
}

TEST(JoinPath, SingleSeparator) {
  EXPECT_EQ(JoinPath("take", "skull.csv"), "take/skull.csv");
  EXPECT_EQ(JoinPath("take/", "skull.csv"), "take/skull.csv");
  EXPECT_EQ(JoinPath("", "skull.csv"), "skull.csv");
  EXPECT_EQ(JoinPath("/", "tmp"), "/tmp");
}

TEST(LowercaseExtension, LastComponentOnly) {
  EXPECT_EQ(LowercaseExtension("take/frame.PLY"), ".ply");
  EXPECT_EQ(LowercaseExtension("weights.Json"), ".json");
  EXPECT_EQ(LowercaseExtension("a.tar.GZ"), ".gz");
  EXPECT_EQ(LowercaseExtension("take"), "");
  EXPECT_EQ(LowercaseExtension("dir.v2/take"), "");
  EXPECT_EQ(LowercaseExtension(".hidden"), "");
  EXPECT_EQ(LowercaseExtension(""), "");
}

TEST(WriteJsonFile, PrettyOrderedAndParseable) {
  TempDir dir;
  const std::string path = dir.Join("out.json");
  Json json;
  json["zeta"] = 1;
  json["alpha"] = Json::array({1.5, "two"});
  json["nested"] = {{"b", true}, {"a", nullptr}};
  ASSERT_TRUE(WriteJsonFile(path, json).ok());
  const std::string text = ReadBytes(path);
  EXPECT_EQ(text,
            "{\n"
            "  \"zeta\": 1,\n"
            "  \"alpha\": [\n"
            "    1.5,\n"
            "    \"two\"\n"
            "  ],\n"
            "  \"nested\": {\n"
            "    \"b\": true,\n"
            "    \"a\": null\n"
            "  }\n"
            "}\n");
  EXPECT_EQ(Json::parse(text), json);
}

// Issue 18, item 5: a short write (the disk filled mid-record) is rolled back, so the log
// never holds a fragment. RLIMIT_FSIZE in a child process makes the write stop part-way (EFBIG)
// exactly as ENOSPC does.
TEST(AppendLogLine, ShortWriteIsRolledBack) {
  TempDir dir;
  const std::string path = dir.Join("log.jsonl");
  WriteBytes(path, "{\"event\":\"a\"}\n");
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::signal(SIGXFSZ, SIG_IGN);
    auto fd = OpenAppendLog(path);
    if (!fd.ok()) ::_exit(3);
    struct rlimit limit {};
    limit.rlim_cur = limit.rlim_max = 16 + 10;  // room for 10 bytes of a 100-byte record
    if (::setrlimit(RLIMIT_FSIZE, &limit) != 0) ::_exit(4);
    const Status appended = AppendLogLine(*fd, std::string(99, 'x') + "\n", path);
    ::_exit(appended.ok() ? 1 : 0);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "the short write was not reported";
  EXPECT_EQ(ReadBytes(path), "{\"event\":\"a\"}\n");  // the 10 bytes were rolled back
}

TEST(OpenAppendLog, FileWithoutAnyNewlineIsAllFragment) {
  TempDir dir;
  const std::string path = dir.Join("log.jsonl");
  WriteBytes(path, "{\"eve");
  size_t torn = 0;
  auto fd = OpenAppendLog(path, &torn);
  ASSERT_TRUE(fd.ok()) << fd.status().ToString();
  ::close(*fd);
  EXPECT_EQ(torn, 5u);
  EXPECT_EQ(ReadBytes(path), "");
  EXPECT_EQ(ReadBytes(path + ".torn"), "{\"eve\n");
}

}  // namespace
}  // namespace facedyn
