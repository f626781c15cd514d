#pragma once
// The CSV text format shared by tables (csv.cpp) and records (records/): lines,
// header, fields parsed in place with std::from_chars, and messages naming the
// row (1-based line of the file) and column.
#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "modalwatch/error.hpp"
#include "modalwatch/io/csv.hpp"

namespace modalwatch::csv_text {
struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

inline std::string read_file(const std::string& path) {
  File f(std::fopen(path.c_str(), "rb"));
  if (!f) throw InputError(path, std::string("cannot open: ") + std::strerror(errno));
  // One allocation of the file's size, then one read (growing a string chunk
  // by chunk costs as much as parsing).
  std::string text;
  if (std::fseek(f.get(), 0, SEEK_END) == 0) {
    const long size = std::ftell(f.get());
    if (size > 0) text.resize(static_cast<std::size_t>(size));
    std::rewind(f.get());
  }
  std::size_t used = std::fread(text.data(), 1, text.size(), f.get());
  text.resize(used);
  char buffer[1 << 16];  // the file may have grown, or not be seekable
  for (std::size_t got = 0; (got = std::fread(buffer, 1, sizeof buffer, f.get())) > 0;) text.append(buffer, got);
  if (std::ferror(f.get())) throw InputError(path, std::string("cannot read: ") + std::strerror(errno));
  return text;
}

inline std::string_view trim(std::string_view s) {
  const auto blank = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
  while (!s.empty() && blank(s.front())) s.remove_prefix(1);
  while (!s.empty() && blank(s.back())) s.remove_suffix(1);
  return s;
}

inline bool is_blank(std::string_view line) { return trim(line).empty(); }

// Splits text into lines without copying; a final line without '\n' counts.
class LineReader {
 public:
  explicit LineReader(std::string_view text) : rest_(text) {}
  bool next(std::string_view& line) {
    if (rest_.empty()) return false;
    const std::size_t end = rest_.find('\n');
    line = rest_.substr(0, end);
    rest_.remove_prefix(end == std::string_view::npos ? rest_.size() : end + 1);
    ++number_;
    return true;
  }
  int number() const { return number_; }  // 1-based line number of the last line
  std::string_view rest() const { return rest_; }

 private:
  std::string_view rest_;
  int number_ = 0;
};

inline std::string row_location(const std::string& path, int row) { return path + ": row " + std::to_string(row); }
inline std::string cell_location(const std::string& path, int row, const std::string& column) {
  return row_location(path, row) + ", column '" + column + "'";
}

inline std::string format_number(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.17g", v);
  return buffer;
}

inline std::string join(const std::vector<std::string>& names) {
  std::string out;
  for (const auto& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

inline std::vector<std::string> parse_header(const std::string& path, std::string_view line) {
  std::vector<std::string> columns;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    const std::string_view field = trim(line.substr(start, comma - start));
    if (field.empty())
      throw InputError(row_location(path, 1),
                       "empty column name in header (column " + std::to_string(columns.size() + 1) + ")");
    std::string name(field);
    if (std::find(columns.begin(), columns.end(), name) != columns.end())
      throw InputError(cell_location(path, 1, name), "duplicate column name");
    columns.push_back(std::move(name));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return columns;
}

// Parses one field completely; from_chars rejects '+', so it is skipped here.
inline bool parse_number(std::string_view field, double& value) {
  if (field.size() > 1 && field.front() == '+' && field[1] != '-') field.remove_prefix(1);
  const char* end = field.data() + field.size();
  const auto [ptr, ec] = std::from_chars(field.data(), end, value);
  return ec == std::errc() && ptr == end;
}

inline std::size_t count_newlines(std::string_view text) {
  return static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n'));
}

class TableParser {
 public:
  // nonfinite_ok[c]: column c may hold nan/inf (records passed on to the
  // estimator, which counts them).
  TableParser(const std::string& path, const std::vector<std::string>& columns, std::vector<bool> nonfinite_ok)
      : path_(path), columns_(columns), nonfinite_ok_(std::move(nonfinite_ok)) {}

  // Fills values[0, columns) from the line with 1-based number `row`.
  void parse_row(std::string_view line, int row, double* values) {
    const std::size_t n = columns_.size();
    std::size_t start = 0;
    for (std::size_t c = 0; c < n; ++c) {
      const std::size_t comma = line.find(',', start);
      if (comma == std::string_view::npos && c + 1 < n) short_row(row, c + 1);
      const std::size_t end = c + 1 < n ? comma : line.size();
      if (c + 1 == n && comma != std::string_view::npos) long_row(line, row);
      values[c] = field(line.substr(start, end - start), row, c);
      start = end + 1;
    }
  }

 private:
  double field(std::string_view text, int row, std::size_t c) const {
    const std::string_view s = trim(text);
    double value = 0.0;
    if (!parse_number(s, value))
      throw InputError(cell_location(path_, row, columns_[c]),
                       s.empty() ? "empty field" : "not a number (got '" + std::string(s) + "')");
    if (!std::isfinite(value) && !nonfinite_ok_[c])
      throw InputError(cell_location(path_, row, columns_[c]), "not a finite number (got '" + std::string(s) + "')");
    return value;
  }
  [[noreturn]] void short_row(int row, std::size_t fields) const {
    throw InputError(cell_location(path_, row, columns_[fields]),
                     "row has " + std::to_string(fields) + " fields, header has " + std::to_string(columns_.size()));
  }
  [[noreturn]] void long_row(std::string_view line, int row) const {
    const std::size_t fields = static_cast<std::size_t>(std::count(line.begin(), line.end(), ',')) + 1;
    throw InputError(row_location(path_, row),
                     "row has " + std::to_string(fields) + " fields, header has " + std::to_string(columns_.size()));
  }

  const std::string& path_;
  const std::vector<std::string>& columns_;
  std::vector<bool> nonfinite_ok_;
};

// Blank lines are accepted only at the end, so that data row k is file line k + 2.
// `lines`: a LineReader, or CsvRecordStream's reader (next(line), number()).
template <class Lines>
inline void check_trailing_blank(const std::string& path, Lines& lines) {
  std::string_view line;
  const int first_blank = lines.number();
  while (lines.next(line))
    if (!is_blank(line)) throw InputError(row_location(path, first_blank), "empty row before more data");
}

inline constexpr std::string_view kBom = "\xEF\xBB\xBF";  // UTF-8 byte order mark
// A file of nothing but these is "empty".
inline constexpr std::string_view kBlankOrBom = " \t\r\n\xEF\xBB\xBF";

inline std::string_view strip_bom(std::string_view text) {
  if (text.substr(0, kBom.size()) == kBom) text.remove_prefix(kBom.size());
  return text;
}

// parse_table, with nan/inf accepted in every column except `finite_column`
// when allow_nonfinite is set. `path` names the source in messages.
inline Table parse_text(std::string_view text, const std::string& path, bool allow_nonfinite,
                        const std::string& finite_column) {
  LineReader lines(strip_bom(text));
  std::string_view line;
  if (text.find_first_not_of(kBlankOrBom) == std::string_view::npos || !lines.next(line))
    throw InputError(path, "empty file (expected a header line of column names)");
  Table table;
  table.columns = parse_header(path, line);
  table.data.resize(static_cast<Eigen::Index>(count_newlines(lines.rest()) + 1),
                    static_cast<Eigen::Index>(table.columns.size()));
  std::vector<bool> nonfinite_ok(table.columns.size(), allow_nonfinite);
  if (const int c = table.column(finite_column); c >= 0) nonfinite_ok[static_cast<std::size_t>(c)] = false;
  TableParser parser(path, table.columns, std::move(nonfinite_ok));
  std::vector<double> values(table.columns.size());
  Eigen::Index rows = 0;
  while (lines.next(line)) {
    if (is_blank(line)) {
      check_trailing_blank(path, lines);
      break;
    }
    parser.parse_row(line, lines.number(), values.data());
    for (std::size_t c = 0; c < values.size(); ++c) table.data(rows, static_cast<Eigen::Index>(c)) = values[c];
    ++rows;
  }
  if (rows == 0) throw InputError(path, "no data rows after the header");
  table.data.conservativeResize(rows, Eigen::NoChange);
  return table;
}

inline int require_column(const std::string& path, const std::vector<std::string>& columns, const std::string& name) {
  const auto it = std::find(columns.begin(), columns.end(), name);
  if (it == columns.end())
    throw MissingColumnError(path, name, columns, "missing column '" + name + "' (available: " + join(columns) + ")");
  return static_cast<int>(it - columns.begin());
}

}  // namespace modalwatch::csv_text
