#pragma once
// Records, read one way: a CSV file (a header line, then t, u, y and, in closed
// loop, r) or an LCM log written by lcm-logger (sample_t / sample_batch_t
// events), told apart by content (the LCM sync word), not by file name. A
// record is read whole (read_record) or as a stream of blocks (RecordReader),
// each block a Record of consecutive samples, with the same checks for both
// formats. Errors are InputErrors naming the file and the row and column (CSV)
// or the byte offset of the event (LCM log).
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "modalwatch/io/csv.hpp"
#include "modalwatch/record.hpp"

namespace modalwatch {

// The CSV columns that hold t, u, y and r, and with several measured inputs
// the columns of the inputs after u, in order (Record::further_u). An LCM log
// has fixed fields: its inputs are the messages' u in order, as many as the
// columns name (the model's inputs; their names do not apply).
struct RecordColumns {
  std::string t = "t", u = "u", y = "y", r = "r";
  std::vector<std::string> further_u;
  bool operator==(const RecordColumns&) const = default;
};

// Where a record comes from.
struct RecordSource {
  RecordSource(std::string path_, RecordColumns columns_ = {}, std::string channel_ = {}, bool closed_loop_ = false)
      : path(std::move(path_)), columns(std::move(columns_)), channel(std::move(channel_)), closed_loop(closed_loop_) {}
  std::string path;
  RecordColumns columns;     // CSV: the column names
  std::string channel;       // LCM log: only this channel (empty: the one channel with samples)
  bool closed_loop = false;  // LCM log: keep r (a CSV has r when it has the column)
};

// What a reader tolerates. The offline commands need clean, equidistant data;
// `track` and `replay` pass NaN/Inf samples and time gaps on to the estimator,
// which counts them (the reader still rejects non-numeric text, and time that
// does not increase).
struct RecordReadOptions {
  bool allow_nonfinite = false;  // NaN, Inf in u, y, r are kept as values
  bool allow_gaps = false;       // steps longer than the nominal one are kept
  double sample_time = 0.0;      // nominal step for allow_gaps (0: the median step)
};

enum class RecordFormat { csv, lcm_log };
// By content: an LCM log starts with the sync word; anything else is CSV.
RecordFormat record_format(const std::string& path);

// The whole record. Time increases strictly; with !allow_gaps evenly (within
// 1 % of the mean step, and 1.5 us more for an LCM log's microsecond clock);
// with !allow_nonfinite u, y, r are finite. For an LCM log a line on stderr
// says how many samples and which events were skipped.
Record read_record(const RecordSource& source, const RecordReadOptions& options = {});
// A CSV record from text in memory; `name` names it in messages.
Record parse_record(std::string_view text, const std::string& name, const RecordColumns& columns = {},
                    const RecordReadOptions& options = {});

// A record as a stream of blocks (every input of the source's columns in each
// block's further_u), so that a long CSV record is never held
// whole: `modalwatch track` estimates while it reads. A CSV record is parsed a
// chunk of the file at a time and checked as the rows arrive (the header and
// columns when the reader is opened, a row's errors when read() reaches it);
// an LCM log is read whole when opened (its events carry no row order to
// stream by) and handed out in blocks. Needs options.allow_gaps and a nominal
// options.sample_time: an evenness check or a median step would need the
// whole record.
class RecordReader {
 public:
  RecordReader(const RecordSource& source, const RecordReadOptions& options);
  RecordReader(RecordReader&&) noexcept;
  RecordReader& operator=(RecordReader&&) noexcept;
  ~RecordReader();

  bool has_reference() const;
  // Replaces `block` with the next samples, at most max_samples (> 0); returns
  // their number, 0 at the end of the record (a record without samples throws).
  // Blocks of the same size reuse block's storage.
  std::size_t read(Record& block, std::size_t max_samples);
  // How much of the record has been read, in [0, 1]; nothing when the size is
  // unknown (a CSV record from a pipe).
  std::optional<double> fraction_read() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Whether a record fits the config that estimates it: its step is the
// configured sample time (at least half of the steps within 1 % of it, so that
// gaps do not count), and in closed loop it has r. Blocks are checked as they
// arrive; a wrong rate fails on the first block of at least three samples.
class RecordCheck {
 public:
  // `config` names the configuration in messages.
  RecordCheck(std::string path, double sample_time, bool closed_loop, std::string config);
  void add(const Record& block);
  // The whole record has been added. A failure names the record's median step,
  // for which `source` is read again (only then).
  void finish(const RecordSource& source, const RecordReadOptions& options) const;

 private:
  friend void check_record(const Record&, const std::string&, double, bool, const std::string&);
  void count(const Record& block);
  bool passed() const;
  [[noreturn]] void fail(const Eigen::Ref<const Eigen::VectorXd>& t, const std::string& which) const;
  std::string path_, config_;
  double sample_time_;
  bool closed_loop_;
  bool reference_checked_ = false;
  double last_ = 0.0;
  std::uint64_t samples_ = 0, matching_ = 0;
};
// The same on a record held whole.
void check_record(const Record& record, const std::string& path, double sample_time, bool closed_loop,
                  const std::string& config);

// A signal file named in a config (`type: csv` under simulation.input or
// simulation.reference): a CSV table as it is, or an LCM log's samples as the
// columns t, u, y, r (gaps allowed: the config interpolates). `channel`
// selects the log's channel and is refused for a CSV file.
Table read_signal_file(const std::string& path, const std::string& channel);

// Writes t, [r,] u, y as CSV, atomically (write_table). The input columns are
// `input_names` (model.inputs) when given, else u (one input) or u1, u2, ...
void write_record(const std::string& path, const Record& record, const std::vector<std::string>& input_names = {});

}  // namespace modalwatch
