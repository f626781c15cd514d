#pragma once
// CSV records: a header line, then numeric rows. Errors name the row (1-based
// line number in the file) and the column.
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "modalwatch/record.hpp"

namespace modalwatch {

struct Table {
  std::vector<std::string> columns;
  Eigen::MatrixXd data;  // rows x columns
  int column(const std::string& name) const;  // -1 when absent
};

// Reads a numeric table. Throws InputError naming the row and column for a
// non-numeric field, NaN or Inf, a short or long row, or an empty file.
Table read_table(const std::string& path);
// The same on text already in memory; `source` names it in messages.
Table parse_table(std::string_view text, const std::string& source);

struct RecordColumns {
  std::string t = "t", u = "u", y = "y", r = "r";
};

// What a reader tolerates. The offline commands need clean, equidistant data;
// `track` and `replay` pass NaN/Inf samples and time gaps on to the estimator,
// which counts them (the reader still rejects non-numeric text, and time that
// does not increase).
struct RecordReadOptions {
  bool allow_nonfinite = false;  // "nan", "inf" in u, y, r are kept as values
  bool allow_gaps = false;       // steps longer than the nominal one are kept
  double sample_time = 0.0;      // nominal step for allow_gaps (0: the median step)
};

// Reads t, u, y (and r when present) and checks that time increases strictly and
// evenly (within 1 % of the mean step). Throws InputError.
Record read_record(const std::string& path, const RecordColumns& columns = {},
                   const RecordReadOptions& options = {});
Record parse_record(std::string_view text, const std::string& source, const RecordColumns& columns = {},
                    const RecordReadOptions& options = {});

// Writes atomically (temporary file, then rename), so a failure leaves nothing behind.
void write_table(const std::string& path, const std::vector<std::string>& columns,
                 const Eigen::MatrixXd& data);
void write_record(const std::string& path, const Record& record);

}  // namespace modalwatch
