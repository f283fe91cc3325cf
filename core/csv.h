// Minimal CSV for facedyn's own tables (skull.csv, skin_samples.csv, markers.csv, telemetry):
// a fixed header line, comma-separated fields, no quoting. Errors name file, line and column.
#pragma once

#include <string>
#include <vector>

#include "core/status.h"

namespace facedyn {

class CsvTable {
 public:
  // Reads `path`, requiring its first line to equal `header` (comma-separated column names).
  // Blank lines are skipped; every other line must have as many fields as the header.
  static StatusOr<CsvTable> Read(const std::string& path, const std::string& header);
  // The same for files whose columns are data (one per blendshape, say): the first line is
  // the header, whatever it names; the caller checks the names through columns().
  static StatusOr<CsvTable> ReadWithHeader(const std::string& path);

  const std::vector<std::string>& columns() const { return columns_; }

  size_t row_count() const { return rows_.size(); }
  const std::string& path() const { return path_; }
  int line_of(size_t row) const { return line_numbers_[row]; }
  const std::string& Text(size_t row, size_t column) const { return rows_[row][column]; }
  // A finite number, or an error "<file>:<line>: column <name> is 'x', not a finite number".
  StatusOr<double> Number(size_t row, size_t column) const;
  // An integer (no fractional part, fits in int).
  StatusOr<int> Integer(size_t row, size_t column) const;
  // DataLoss "<file>:<line>: <message>".
  Status RowError(size_t row, const std::string& message) const;

 private:
  static StatusOr<CsvTable> ReadImpl(const std::string& path, const std::string* expected_header);

  std::string path_;
  std::vector<std::string> columns_;
  std::vector<std::vector<std::string>> rows_;
  std::vector<int> line_numbers_;
};

}  // namespace facedyn
