#pragma once
// Records for the subcommands: CSV (t,u,y[,r]) or an LCM log written by
// lcm-logger, told apart by content (the LCM sync word), not by file name.
#include <optional>
#include <string>

#include "modalwatch/io/config.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/record.hpp"

namespace modalwatch::cli {

struct RecordSource {
  std::string path;
  std::string channel;       // LCM logs: only this channel (empty: any channel with samples)
  bool closed_loop = false;  // LCM logs: keep r (a CSV has it as a column)
  RecordColumns columns;     // CSV: the column names (an LCM log has fixed fields)
};

// The same checks for both formats: time increases; with !allow_gaps evenly
// (within 1 % of the mean step); with !allow_nonfinite no NaN/Inf. Errors name
// the row (CSV) or the byte offset of the event (LCM). For an LCM log a line on
// stderr says how many samples and which events were skipped.
Record load_record(const RecordSource& source, const RecordReadOptions& options = {});

// A CSV record opened as a stream of row blocks (header and columns checked),
// or nothing when `source` is an LCM log (read those whole with load_record).
// The stream needs options.allow_gaps and options.sample_time (RecordStream).
std::optional<RecordStream> open_csv_stream(const RecordSource& source, const RecordReadOptions& options);

// A signal file named in a config (`type: csv`): a CSV table as it is, or an LCM
// log's samples as the columns t, u, y, r (gaps allowed: the config
// interpolates). `channel` selects the log's channel.
Table read_signal_file(const std::string& path, const std::string& channel);

// load_config for the subcommands: signal files may be LCM logs too.
inline Config load_cli_config(const std::string& path) { return load_config(path, read_signal_file); }

}  // namespace modalwatch::cli
