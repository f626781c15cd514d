#pragma once
// CSV tables: a header line, then numeric rows (records: records.hpp). Errors
// name the row (1-based line number in the file) and the column.
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "modalwatch/error.hpp"

namespace modalwatch {

struct Table {
  std::vector<std::string> columns;
  Eigen::MatrixXd data;                       // rows x columns
  int column(const std::string& name) const;  // -1 when absent
};

// A column a reader needs is not in the header; the command line that chose the
// name can say which option picks another.
class MissingColumnError : public InputError {
 public:
  MissingColumnError(const std::string& path, std::string column, std::vector<std::string> available,
                     const std::string& message)
      : InputError(path, message), column_(std::move(column)), available_(std::move(available)) {}
  const std::string& column() const { return column_; }
  const std::vector<std::string>& available() const { return available_; }

 private:
  std::string column_;
  std::vector<std::string> available_;
};

// Reads a numeric table. Throws InputError naming the row and column for a
// non-numeric field, NaN or Inf, a short or long row, or an empty file.
Table read_table(const std::string& path);
// The same on text already in memory; `source` names it in messages.
Table parse_table(std::string_view text, const std::string& source);

// Writes atomically (temporary file, then rename), so a failure leaves nothing behind.
void write_table(const std::string& path, const std::vector<std::string>& columns, const Eigen::MatrixXd& data);

}  // namespace modalwatch
