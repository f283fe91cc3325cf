// CsvTable: facedyn's fixed-header CSV reader, and the messages that name file, line, column.
#include "core/csv.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

constexpr char kHeader[] = "name,count,value";

TEST(CsvTableRead, RowsFieldsAndLineNumbers) {
  TempDir dir;
  const std::string path = dir.Join("table.csv");
  // A blank line is skipped but still counted; Windows line endings are accepted.
  WriteBytes(path, "name,count,value\r\nalpha,1,0.5\r\n\nbeta,-2,1e-3\ngamma,3,\n");
  // The last row has an empty value: 3 fields, read as text, rejected as a number.
  const auto table = CsvTable::Read(path, kHeader);
  ASSERT_TRUE(table.ok()) << table.status().message();
  EXPECT_EQ(table->path(), path);
  ASSERT_EQ(table->row_count(), 3u);
  EXPECT_EQ(table->Text(0, 0), "alpha");
  EXPECT_EQ(table->Text(0, 2), "0.5");  // no trailing '\r'
  EXPECT_EQ(table->Text(1, 0), "beta");
  EXPECT_EQ(table->Text(2, 2), "");
  EXPECT_EQ(table->line_of(0), 2);
  EXPECT_EQ(table->line_of(1), 4);
  EXPECT_EQ(table->line_of(2), 5);
  EXPECT_EQ(*table->Number(0, 2), 0.5);
  EXPECT_EQ(*table->Number(1, 2), 1e-3);
  EXPECT_EQ(*table->Integer(1, 1), -2);
  const auto empty = table->Number(2, 2);
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.status().message(), path + ":5: column value is '', not a finite number");
}

TEST(CsvTableRead, HeaderOnlyIsAnEmptyTable) {
  TempDir dir;
  const std::string path = dir.Join("table.csv");
  WriteBytes(path, "name,count,value\n");
  const auto table = CsvTable::Read(path, kHeader);
  ASSERT_TRUE(table.ok()) << table.status().message();
  EXPECT_EQ(table->row_count(), 0u);
}

TEST(CsvTableRead, InvalidUtf8IsAnErrorNamingLineAndByte) {
  TempDir dir;
  const std::string path = dir.Join("table.csv");
  WriteBytes(path, "name,count,value\nnose_tip,1,2\nbrow_\xff,3,4\n");
  const auto table = CsvTable::Read(path, kHeader);
  ASSERT_FALSE(table.ok());
  EXPECT_EQ(table.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(table.status().message(), HasSubstr(path + ":3: byte 6 is not valid UTF-8"));
}

TEST(CsvTableRead, MissingFile) {
  TempDir dir;
  const auto table = CsvTable::Read(dir.Join("absent.csv"), kHeader);
  ASSERT_FALSE(table.ok());
  EXPECT_EQ(table.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(table.status().message(), HasSubstr(dir.Join("absent.csv")));
}

TEST(CsvTableRead, EmptyFile) {
  TempDir dir;
  const std::string path = dir.Join("empty.csv");
  WriteBytes(path, "");
  const auto table = CsvTable::Read(path, kHeader);
  ASSERT_FALSE(table.ok());
  EXPECT_EQ(table.status().code(), StatusCode::kDataLoss);
  EXPECT_EQ(table.status().message(),
            path + ": empty file, expected the header 'name,count,value'");
}

TEST(CsvTableRead, WrongHeader) {
  TempDir dir;
  const std::string path = dir.Join("table.csv");
  WriteBytes(path, "name,value,count\nalpha,1,2\n");
  const auto table = CsvTable::Read(path, kHeader);
  ASSERT_FALSE(table.ok());
  EXPECT_EQ(table.status().message(),
            path + ":1: header is 'name,value,count', expected 'name,count,value'");
}

TEST(CsvTableRead, WrongFieldCount) {
  TempDir dir;
  const std::string path = dir.Join("table.csv");
  WriteBytes(path, "name,count,value\nalpha,1,2\nbeta,2\n");
  auto table = CsvTable::Read(path, kHeader);
  ASSERT_FALSE(table.ok());
  EXPECT_EQ(table.status().message(), path + ":3: expected 3 comma-separated fields, got 2");
  // A trailing comma is an extra (empty) field.
  WriteBytes(path, "name,count,value\nalpha,1,2,\n");
  table = CsvTable::Read(path, kHeader);
  ASSERT_FALSE(table.ok());
  EXPECT_EQ(table.status().message(), path + ":2: expected 3 comma-separated fields, got 4");
}

TEST(CsvTableNumber, RejectsWhatIsNotAFiniteNumber) {
  TempDir dir;
  const std::string path = dir.Join("table.csv");
  WriteBytes(path, "name,count,value\na,1,abc\nb,1,1.5x\nc,1,inf\nd,1,nan\ne,1,-0.25\n");
  const auto table = CsvTable::Read(path, kHeader);
  ASSERT_TRUE(table.ok()) << table.status().message();
  const char* bad[] = {"abc", "1.5x", "inf", "nan"};
  for (size_t row = 0; row < 4; ++row) {
    const auto value = table->Number(row, 2);
    ASSERT_FALSE(value.ok()) << bad[row];
    EXPECT_EQ(value.status().code(), StatusCode::kDataLoss);
    EXPECT_EQ(value.status().message(), path + ":" + std::to_string(row + 2) +
                                            ": column value is '" + bad[row] +
                                            "', not a finite number");
  }
  EXPECT_EQ(*table->Number(4, 2), -0.25);
}

TEST(CsvTableInteger, RejectsFractionsAndOverflow) {
  TempDir dir;
  const std::string path = dir.Join("table.csv");
  WriteBytes(path, "name,count,value\na,2.5,0\nb,3e9,0\nc,1e2,0\nd,-4,0\ne,x,0\n");
  const auto table = CsvTable::Read(path, kHeader);
  ASSERT_TRUE(table.ok()) << table.status().message();
  EXPECT_EQ(table->Integer(0, 1).status().message(),
            path + ":2: column count is '2.5', not an integer");
  EXPECT_EQ(table->Integer(1, 1).status().message(),
            path + ":3: column count is '3e9', not an integer");
  EXPECT_EQ(*table->Integer(2, 1), 100);
  EXPECT_EQ(*table->Integer(3, 1), -4);
  EXPECT_THAT(table->Integer(4, 1).status().message(), HasSubstr("not a finite number"));
}

TEST(CsvTableRowError, NamesFileAndLine) {
  TempDir dir;
  const std::string path = dir.Join("table.csv");
  WriteBytes(path, "name,count,value\n\n\na,1,2\n");
  const auto table = CsvTable::Read(path, kHeader);
  ASSERT_TRUE(table.ok()) << table.status().message();
  const Status status = table->RowError(0, "frame 0: something is off");
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_EQ(status.message(), path + ":4: frame 0: something is off");
}

}  // namespace
}  // namespace facedyn
