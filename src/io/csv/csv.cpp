// CSV tables. The whole file is read into memory and parsed in place with
// std::from_chars (csv_text.hpp): iostream per field is an order of magnitude
// too slow for records of millions of rows.
#include "modalwatch/io/csv.hpp"

#include <charconv>
#include <string>
#include <system_error>

#include "csv_text.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/io/atomic_file.hpp"

namespace modalwatch {

using csv_text::parse_text;
using csv_text::read_file;

int Table::column(const std::string& name) const {
  const auto it = std::find(columns.begin(), columns.end(), name);
  return it == columns.end() ? -1 : static_cast<int>(it - columns.begin());
}

Table parse_table(std::string_view text, const std::string& source) { return parse_text(text, source, false, ""); }

Table read_table(const std::string& path) { return parse_table(read_file(path), path); }

namespace {

// std::to_chars with precision 17 prints what %.17g prints, several times faster
// than fprintf; rows are buffered and written in large blocks.
void write_rows(AtomicFile& f, const std::vector<std::string>& columns, const Eigen::MatrixXd& data) {
  std::string out;
  for (std::size_t j = 0; j < columns.size(); ++j) (out += j == 0 ? "" : ",") += columns[j];
  out += '\n';
  char field[64];
  for (Eigen::Index i = 0; i < data.rows(); ++i) {
    for (Eigen::Index j = 0; j < data.cols(); ++j) {
      if (j > 0) out += ',';
      const auto end = std::to_chars(field, field + sizeof field, data(i, j), std::chars_format::general, 17).ptr;
      out.append(field, end);
    }
    out += '\n';
    if (out.size() > (1 << 16)) {
      f.write(out);
      out.clear();
    }
  }
  f.write(out);
}

// The header has no quoting, so names that would split or shift columns are refused.
void check_columns(const std::string& path, const std::vector<std::string>& columns, const Eigen::MatrixXd& data) {
  if (static_cast<Eigen::Index>(columns.size()) != data.cols())
    throw InputError(path, "cannot write: " + std::to_string(columns.size()) + " column names for " +
                               std::to_string(data.cols()) + " columns");
  for (const auto& name : columns)
    if (name.empty() || name.find_first_of(",\n\r") != std::string::npos || csv_text::trim(name) != name)
      throw InputError(path, "cannot write: invalid column name '" + name + "'");
}

}  // namespace

void write_table(const std::string& path, const std::vector<std::string>& columns, const Eigen::MatrixXd& data) {
  check_columns(path, columns, data);
  try {
    AtomicFile file(path);
    write_rows(file, columns, data);
    file.commit();
  } catch (const std::system_error& e) {
    throw InputError(path, std::string("cannot write: ") + e.code().message());
  }
}

}  // namespace modalwatch
