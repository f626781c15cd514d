#pragma once
// CSV tables: a header line, then numeric rows (records: records.hpp). Errors
// name the row (1-based line number in the file) and the column.
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

namespace modalwatch {

struct Table {
  std::vector<std::string> columns;
  Eigen::MatrixXd data;                       // rows x columns
  int column(const std::string& name) const;  // -1 when absent
};

// Reads a numeric table. Throws InputError naming the row and column for a
// non-numeric field, NaN or Inf, a short or long row, or an empty file.
Table read_table(const std::string& path);
// The same on text already in memory; `source` names it in messages.
Table parse_table(std::string_view text, const std::string& source);

// Writes atomically (temporary file, then rename), so a failure leaves nothing behind.
void write_table(const std::string& path, const std::vector<std::string>& columns, const Eigen::MatrixXd& data);

}  // namespace modalwatch
