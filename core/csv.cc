#include "core/csv.h"

#include <fmt/format.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <sstream>

#include "core/file_util.h"
#include "core/utf8.h"

namespace facedyn {
namespace {
std::vector<std::string> Split(const std::string& line) {
  std::vector<std::string> fields;
  size_t start = 0;
  while (true) {
    const size_t comma = line.find(',', start);
    fields.push_back(line.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return fields;
}
}  // namespace

StatusOr<CsvTable> CsvTable::Read(const std::string& path, const std::string& header) {
  return ReadImpl(path, &header);
}

StatusOr<CsvTable> CsvTable::ReadWithHeader(const std::string& path) { return ReadImpl(path, nullptr); }

StatusOr<CsvTable> CsvTable::ReadImpl(const std::string& path, const std::string* expected_header) {
  FACEDYN_ASSIGN_OR_RETURN(const std::string text, ReadFileToString(path));
  CsvTable table;
  table.path_ = path;
  if (expected_header != nullptr) table.columns_ = Split(*expected_header);
  std::stringstream stream(text);
  std::string line;
  int line_number = 0;
  bool have_header = false;
  while (std::getline(stream, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    // Field text (marker names, labels) reaches JSON reports, which must be UTF-8.
    size_t bad_byte = 0;
    if (!IsValidUtf8(line, &bad_byte)) {
      return DataLossError(
          fmt::format("{}:{}: byte {} is not valid UTF-8 (CSV files are UTF-8 text)", path,
                      line_number, bad_byte + 1));
    }
    if (!have_header) {
      if (expected_header == nullptr) {
        if (line.empty()) continue;
        table.columns_ = Split(line);
      } else if (line != *expected_header) {
        return DataLossError(fmt::format("{}:{}: header is '{}', expected '{}'", path, line_number,
                                         line, *expected_header));
      }
      have_header = true;
      continue;
    }
    if (line.empty()) continue;
    auto fields = Split(line);
    if (fields.size() != table.columns_.size()) {
      return DataLossError(fmt::format("{}:{}: expected {} comma-separated fields, got {}", path,
                                       line_number, table.columns_.size(), fields.size()));
    }
    table.rows_.push_back(std::move(fields));
    table.line_numbers_.push_back(line_number);
  }
  if (!have_header) {
    return DataLossError(path + ": empty file, expected " +
                         (expected_header ? "the header '" + *expected_header + "'" : "a header line"));
  }
  return table;
}

StatusOr<double> CsvTable::Number(size_t row, size_t column) const {
  const std::string& text = rows_[row][column];
  char* end = nullptr;
  const double value = text.empty() ? 0.0 : std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(value)) {
    return RowError(row, fmt::format("column {} is '{}', not a finite number", columns_[column], text));
  }
  return value;
}

StatusOr<int> CsvTable::Integer(size_t row, size_t column) const {
  FACEDYN_ASSIGN_OR_RETURN(const double value, Number(row, column));
  if (value != std::floor(value) || std::abs(value) > std::numeric_limits<int>::max()) {
    return RowError(row, fmt::format("column {} is '{}', not an integer", columns_[column], rows_[row][column]));
  }
  return static_cast<int>(value);
}

Status CsvTable::RowError(size_t row, const std::string& message) const {
  return DataLossError(fmt::format("{}:{}: {}", path_, line_numbers_[row], message));
}

}  // namespace facedyn
