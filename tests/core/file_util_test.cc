// File helpers: reads that say what went wrong, atomic writes, directories, paths; and the
// JSON writer built on them.
#include "core/file_util.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

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

}  // namespace
}  // namespace facedyn
