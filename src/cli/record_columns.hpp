#pragma once
// The CSV columns the offline commands (fit, diagnose) read as t, u and y,
// chosen with --t-column, --u-column and --y-column, and the reader that names
// those options when a record lacks the column.
#include <string>

#include "modalwatch/error.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/io/records.hpp"

namespace modalwatch::cli {

struct ColumnArgs {
  std::string t = "t", u = "u", y = "y";  // e.g. n (sample index), u1, y2
};

inline RecordColumns record_columns(const ColumnArgs& args) {
  RecordColumns columns;
  columns.t = args.t;
  columns.u = args.u;
  columns.y = args.y;
  return columns;
}

// A record without a sample rate: its time column, named otherwise than t, counts
// samples (whole numbers one apart, as sample_rate_hz: 1 checks), and its
// frequencies are in cycles/sample rather than Hz.
inline bool time_in_samples(const Record& r, const ColumnArgs& columns, double sample_time) {
  if (columns.t == "t" || sample_time != 1.0) return false;
  return (r.t.array() == r.t.array().round()).all();
}

inline const char* frequency_unit(bool in_samples) { return in_samples ? "cycles/sample" : "Hz"; }

inline Record read_record_with_columns(const RecordSource& source) {
  try {
    return read_record(source);
  } catch (const MissingColumnError& e) {
    const char* option = e.column() == source.columns.t   ? "--t-column"
                         : e.column() == source.columns.u ? "--u-column"
                         : e.column() == source.columns.y ? "--y-column"
                                                          : nullptr;
    if (!option) throw;
    std::string message = e.what();
    if (!e.location().empty() && message.starts_with(e.location() + ": "))
      message.erase(0, e.location().size() + 2);
    throw InputError(e.location(), message + "; pick one with " + option);
  }
}

}  // namespace modalwatch::cli
