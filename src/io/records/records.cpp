// Records from CSV files and LCM logs (records.hpp): the format by content,
// then the one reader for it; the checks that differ in how a format locates a
// sample (a CSV row, an LCM event's byte offset) but not in what they accept.
#include "modalwatch/io/records.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <utility>
#include <variant>
#include <vector>

#include "../csv/csv_text.hpp"
#include "csv_record.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/io/lcm_log.hpp"

namespace modalwatch {
namespace {

void check_csv_source(const RecordSource& source) {
  if (!source.channel.empty())
    throw InputError("--channel", "applies to LCM logs only; " + source.path + " is not one (no LCM sync word)");
}

// An LCM log's samples, checked as a CSV record is: one channel, finite values
// (unless allowed), even time (unless gaps are allowed). Its inputs are the
// message's u, in order: the columns name as many inputs (the model's), whatever
// their names; t, y and r cannot be renamed.
Record read_lcm_record(const RecordSource& source, const RecordReadOptions& options) {
  const RecordColumns& columns = source.columns;
  const RecordColumns plain;
  if (columns.t != plain.t || columns.y != plain.y || columns.r != plain.r ||
      (columns.further_u.empty() && columns.u != plain.u))
    throw InputError(source.path, "LCM log: column options apply to CSV records only (an LCM log has u, y, r)");
  LcmLogOptions lo;
  lo.channel = source.channel;
  lo.closed_loop = source.closed_loop;
  lo.inputs = 1 + static_cast<int>(columns.further_u.size());
  LcmLogRecord log = read_lcm_log(source.path, lo);
  const Record& rec = log.record;
  const auto where = [&](Eigen::Index k) {
    return "LCM log: byte offset " + std::to_string(log.offsets[static_cast<std::size_t>(k)]) + ": sample " +
           std::to_string(k + 1);
  };
  if (log.channels.size() > 1 && source.channel.empty()) {
    std::string list;
    for (const auto& c : log.channels) list += (list.empty() ? "'" : ", '") + c + "'";
    throw InputError(source.path, "LCM log: samples on several channels (" + list + "): choose one with --channel");
  }
  if (!options.allow_nonfinite) {
    for (Eigen::Index k = 0; k < rec.size(); ++k) {
      bool finite = std::isfinite(rec.y(k)) && (!rec.has_reference() || std::isfinite(rec.r(k)));
      for (int j = 0; j < rec.inputs(); ++j) finite = finite && std::isfinite(rec.input(j)(k));
      if (!finite) throw InputError(source.path, where(k) + ": NaN or Inf in u, y or r");
    }
  }
  const Eigen::Index n = rec.size();
  if (!options.allow_gaps && n >= 3) {
    const double mean = (rec.t(n - 1) - rec.t(0)) / static_cast<double>(n - 1);
    for (Eigen::Index k = 1; k < n; ++k) {
      const double step = rec.t(k) - rec.t(k - 1);
      // utime has 1 us resolution: allow that on top of the CSV reader's 1 %.
      if (std::abs(step - mean) > 0.01 * mean + 1.5e-6)
        throw InputError(source.path, where(k) + ": time step " + std::to_string(step) + " s, mean step " +
                                          std::to_string(mean) + " s: the record is not equidistant (gap?)");
    }
  }
  std::fprintf(stderr,
               "modalwatch: %lld samples from LCM log %s (channel %s; %llu events, skipped: %llu other channel, "
               "%llu other type, %llu of another number of inputs, %llu invalid, %llu samples out of order or "
               "duplicate)\n",
               static_cast<long long>(n), source.path.c_str(), log.channels.front().c_str(),
               static_cast<unsigned long long>(log.events), static_cast<unsigned long long>(log.skipped_channel),
               static_cast<unsigned long long>(log.skipped_type), static_cast<unsigned long long>(log.skipped_inputs),
               static_cast<unsigned long long>(log.skipped_invalid),
               static_cast<unsigned long long>(log.skipped_order));
  return std::move(log.record);
}

// An LCM log held whole, handed out in blocks.
struct HeldRecord {
  Record record;
  Eigen::Index next = 0;
};

}  // namespace

RecordFormat record_format(const std::string& path) {
  return is_lcm_log(path) ? RecordFormat::lcm_log : RecordFormat::csv;
}

Record read_record(const RecordSource& source, const RecordReadOptions& options) {
  if (record_format(source.path) == RecordFormat::lcm_log) return read_lcm_record(source, options);
  check_csv_source(source);
  return parse_record(csv_text::read_file(source.path), source.path, source.columns, options);
}

struct RecordReader::Impl {
  std::variant<CsvRecordStream, HeldRecord> reader;
};

RecordReader::RecordReader(const RecordSource& source, const RecordReadOptions& options) {
  if (!options.allow_gaps || !(options.sample_time > 0.0))
    throw std::invalid_argument("RecordReader needs allow_gaps and a nominal sample_time");
  if (record_format(source.path) == RecordFormat::lcm_log) {
    impl_ = std::make_unique<Impl>(Impl{HeldRecord{read_lcm_record(source, options), 0}});
  } else {
    check_csv_source(source);
    impl_ = std::make_unique<Impl>(Impl{CsvRecordStream(source.path, source.columns, options)});
  }
}

RecordReader::RecordReader(RecordReader&&) noexcept = default;
RecordReader& RecordReader::operator=(RecordReader&&) noexcept = default;
RecordReader::~RecordReader() = default;

bool RecordReader::has_reference() const {
  if (const auto* held = std::get_if<HeldRecord>(&impl_->reader)) return held->record.has_reference();
  return std::get<CsvRecordStream>(impl_->reader).has_reference();
}

std::size_t RecordReader::read(Record& block, std::size_t max_samples) {
  auto* held = std::get_if<HeldRecord>(&impl_->reader);
  if (held == nullptr) return std::get<CsvRecordStream>(impl_->reader).read(block, max_samples);
  const Eigen::Index count = std::min(static_cast<Eigen::Index>(max_samples), held->record.size() - held->next);
  const Record& rec = held->record;
  // Assigned member by member, so that a block of the last one's size keeps its storage.
  block.t = rec.t.segment(held->next, count);
  block.u = rec.u.segment(held->next, count);
  block.y = rec.y.segment(held->next, count);
  block.further_u.resize(rec.further_u.size());
  for (std::size_t j = 0; j < rec.further_u.size(); ++j)
    block.further_u[j] = rec.further_u[j].segment(held->next, count);
  if (rec.has_reference())
    block.r = rec.r.segment(held->next, count);
  else
    block.r.resize(0);
  held->next += count;
  return static_cast<std::size_t>(count);
}

std::optional<double> RecordReader::fraction_read() const {
  if (const auto* held = std::get_if<HeldRecord>(&impl_->reader))
    return static_cast<double>(held->next) / static_cast<double>(held->record.size());
  const auto& csv = std::get<CsvRecordStream>(impl_->reader);
  if (csv.file_size() == 0) return std::nullopt;
  return std::min(1.0, static_cast<double>(csv.bytes_read()) / static_cast<double>(csv.file_size()));
}

RecordCheck::RecordCheck(std::string path, double sample_time, bool closed_loop, std::string config)
    : path_(std::move(path)), config_(std::move(config)), sample_time_(sample_time), closed_loop_(closed_loop) {}

void RecordCheck::count(const Record& block) {
  if (!reference_checked_ && block.size() > 0) {
    if (closed_loop_ && !block.has_reference()) throw InputError(path_, "closed loop (model.loop) needs a column 'r'");
    reference_checked_ = true;
  }
  for (Eigen::Index k = 0; k < block.size(); ++k) {
    const double t = block.t(k);
    if (samples_ > 0 && std::abs(t - last_ - sample_time_) <= 0.01 * sample_time_) ++matching_;
    last_ = t;
    ++samples_;
  }
}

bool RecordCheck::passed() const { return samples_ < 3 || 2 * matching_ >= samples_ - 1; }

void RecordCheck::add(const Record& block) {
  const bool first = samples_ == 0;
  count(block);
  // A wrong sample_rate_hz shows in the first block already: say so now
  // rather than after estimating the whole record.
  if (first && !passed()) fail(block.t, "median step of the first " + std::to_string(block.size()) + " rows");
}

void RecordCheck::finish(const RecordSource& source, const RecordReadOptions& options) const {
  if (passed()) return;
  RecordReader reader(source, options);
  std::vector<double> times;
  Record block;
  while (reader.read(block, 1 << 16) > 0) times.insert(times.end(), block.t.begin(), block.t.end());
  fail(Eigen::Map<const Eigen::VectorXd>(times.data(), static_cast<Eigen::Index>(times.size())), "median step");
}

void RecordCheck::fail(const Eigen::Ref<const Eigen::VectorXd>& t, const std::string& which) const {
  std::vector<double> steps;
  for (Eigen::Index k = 1; k < t.size(); ++k) steps.push_back(t(k) - t(k - 1));
  if (steps.empty()) throw InputError(path_, "column 't': the record changed while it was read");
  const auto mid = steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2);
  std::nth_element(steps.begin(), mid, steps.end());
  throw InputError(path_, "column 't': sample time " + std::to_string(*mid) + " s (" + which +
                              ") does not match sample_rate_hz " + std::to_string(1.0 / sample_time_) + " of " +
                              config_);
}

void check_record(const Record& record, const std::string& path, double sample_time, bool closed_loop,
                  const std::string& config) {
  RecordCheck check(path, sample_time, closed_loop, config);
  check.count(record);
  if (!check.passed()) check.fail(record.t, "median step");
}

Table read_signal_file(const std::string& path, const std::string& channel) {
  if (record_format(path) == RecordFormat::csv) {
    if (!channel.empty())
      throw InputError(path, "key 'channel' applies to LCM logs only; this is not one (no LCM sync word)");
    return read_table(path);
  }
  RecordReadOptions options;
  options.allow_gaps = true;
  const Record rec = read_lcm_record(RecordSource(path, {}, channel, true), options);
  Table table;
  table.columns = {"t", "u", "y", "r"};
  table.data.resize(rec.size(), 4);
  table.data.col(0) = rec.t;
  table.data.col(1) = rec.u;
  table.data.col(2) = rec.y;
  table.data.col(3) = rec.r;
  return table;
}

void write_record(const std::string& path, const Record& record, const std::vector<std::string>& input_names) {
  const bool with_r = record.has_reference();
  const Eigen::Index n = record.size();
  const int inputs = record.inputs();
  if (record.u.size() != n || record.y.size() != n) throw InputError(path, "cannot write: t, u and y differ in length");
  for (const auto& v : record.further_u)
    if (v.size() != n) throw InputError(path, "cannot write: the inputs differ in length from t");
  if (!input_names.empty() && static_cast<int>(input_names.size()) != inputs)
    throw InputError(path, "cannot write: " + std::to_string(inputs) + " inputs, " +
                               std::to_string(input_names.size()) + " names");
  std::vector<std::string> columns{"t"};
  Eigen::MatrixXd data(n, 2 + (with_r ? 1 : 0) + inputs);
  Eigen::Index c = 0;
  data.col(c++) = record.t;
  if (with_r) {
    columns.push_back("r");
    data.col(c++) = record.r;
  }
  for (int j = 0; j < inputs; ++j) {
    columns.push_back(!input_names.empty() ? input_names[static_cast<std::size_t>(j)]
                      : inputs == 1        ? std::string("u")
                                           : "u" + std::to_string(j + 1));
    data.col(c++) = record.input(j);
  }
  columns.push_back("y");
  data.col(c) = record.y;
  write_table(path, columns, data);
}

}  // namespace modalwatch