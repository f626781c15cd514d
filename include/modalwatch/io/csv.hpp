#pragma once
// CSV records: a header line, then numeric rows. Errors name the row (1-based
// line number in the file) and the column.
#include <cstddef>
#include <cstdint>
#include <memory>
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

// Rows of a record as a RecordStream delivers them.
struct RecordBlock {
  std::vector<double> t, u, y, r;  // r stays empty when the record has no column r
  std::size_t size() const { return t.size(); }
};

// A CSV record read a block of rows at a time (large reads parsed in place),
// so that a long record is never held whole: `modalwatch track` estimates
// while it reads. The format and checks are read_record's with
// options.allow_gaps and a nominal options.sample_time (both required: a
// median step or an evenness check would need the whole record), applied as
// the rows arrive: the header and columns when the stream is opened, a row's
// errors when read() reaches it (InputError naming the file, line and column).
class RecordStream {
 public:
  RecordStream(const std::string& path, const RecordColumns& columns, const RecordReadOptions& options);
  RecordStream(RecordStream&&) noexcept;
  RecordStream& operator=(RecordStream&&) noexcept;
  ~RecordStream();

  bool has_reference() const;  // the record has the column r
  // Replaces the block's rows with the next ones, at most max_rows (> 0);
  // returns their number, 0 at the end of the record (after at least one row:
  // a record without rows throws).
  std::size_t read(RecordBlock& block, std::size_t max_rows);
  std::uint64_t bytes_read() const;  // of the file, up to the last row read
  std::uint64_t file_size() const;   // 0 when unknown (a pipe)

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Writes atomically (temporary file, then rename), so a failure leaves nothing behind.
void write_table(const std::string& path, const std::vector<std::string>& columns,
                 const Eigen::MatrixXd& data);
void write_record(const std::string& path, const Record& record);

}  // namespace modalwatch
