// `modalwatch track`: the recursive estimator over a record, one row of
// estimates per input sample.
//
// The record is read leniently (NaN/Inf samples and time gaps are passed on to
// the estimator, which counts them) and streamed: a reader thread reads it a
// block of samples at a time (RecordReader) while the estimation loop runs.
// est.csv is formatted by two threads (t and the
// estimates shortest round-trip, their standard deviations to 6 digits:
// number_format.hpp), a block of rows at a time into preallocated buffers,
// written in order to a temporary file and renamed at the end, so a failure
// leaves nothing behind. Progress goes to stderr only when it is a terminal.
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <deque>
#include <exception>
#include <memory>
#include <mutex>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "guarded.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/estimator.hpp"
#include "modalwatch/fault_detector.hpp"
#include "modalwatch/io/atomic_file.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/io/records.hpp"
#include "number_format.hpp"
#include "table.hpp"

namespace modalwatch::cli {
namespace {

using Clock = std::chrono::steady_clock;

// Reads the record on its own thread, a block of samples at a time handed to the
// estimation loop through a bounded queue, so that reading overlaps estimation
// and formatting. The blocks are reused; the threads wait on condition
// variables, never spin (two cores for the reader, the estimation loop and two
// formatters).
class BlockReader {
 public:
  static constexpr std::size_t kRowsPerBlock = 4096;
  static constexpr std::size_t kBlocks = 4;

  explicit BlockReader(RecordReader& stream) : stream_(stream), slots_(kBlocks) {
    for (auto& slot : slots_) free_.push_back(&slot);
    thread_ = std::thread([this] { run(); });
  }
  BlockReader(const BlockReader&) = delete;
  BlockReader& operator=(const BlockReader&) = delete;
  ~BlockReader() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    free_cv_.notify_all();
    thread_.join();
  }

  // The next block of samples, valid until the next call; nullptr at the end
  // of the record. A reading error (a malformed row) is rethrown here once the
  // rows before it have been taken.
  const Record* next() {
    std::unique_lock<std::mutex> lock(mutex_);
    if (current_ != nullptr) {
      free_.push_back(current_);
      current_ = nullptr;
      free_cv_.notify_one();
    }
    filled_cv_.wait(lock, [this] { return !filled_.empty() || done_; });
    if (filled_.empty()) {
      if (error_) std::rethrow_exception(error_);
      return nullptr;
    }
    current_ = filled_.front();
    filled_.pop_front();
    return &current_->rows;
  }
  // Fraction of the record up to the end of the block last returned (progress).
  double fraction_read() const { return current_ != nullptr ? current_->fraction_read : 0.0; }

 private:
  struct Slot {
    Record rows;
    double fraction_read = 0.0;
  };

  void run() {
    for (;;) {
      Slot* slot = nullptr;
      {
        std::unique_lock<std::mutex> lock(mutex_);
        free_cv_.wait(lock, [this] { return stop_ || !free_.empty(); });
        if (stop_) return;
        slot = free_.back();
        free_.pop_back();
      }
      std::size_t rows = 0;
      std::exception_ptr error;
      try {
        rows = stream_.read(slot->rows, kRowsPerBlock);
        slot->fraction_read = stream_.fraction_read().value_or(0.0);
      } catch (...) {
        error = std::current_exception();
      }
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (rows > 0) {
          filled_.push_back(slot);
        } else {
          free_.push_back(slot);
          error_ = error;
          done_ = true;
        }
      }
      filled_cv_.notify_one();
      if (rows == 0) return;
    }
  }

  RecordReader& stream_;
  std::vector<Slot> slots_;
  Slot* current_ = nullptr;  // the estimation loop's
  std::mutex mutex_;
  std::condition_variable filled_cv_, free_cv_;
  std::deque<Slot*> filled_;
  std::vector<Slot*> free_;
  bool done_ = false, stop_ = false;
  std::exception_ptr error_;
  std::thread thread_;
};

// How est.csv writes a column (number_format.hpp).
enum class ColumnFormat {
  kExact,      // shortest round-trip: t, the estimates, residual_rms
  kSixDigits,  // "%.6g": the standard deviations
  kInteger,    // flags, resets
};

// A block of rows formatted into one preallocated buffer.
class RowWriter {
 public:
  // Longest field: a shortest round-trip double ("-2.2250738585072014e-308",
  // 24 characters) or a 64-bit integer (20), plus the separator.
  static constexpr std::size_t kFieldBytes = 32;

  RowWriter(std::size_t rows, std::size_t columns) : buffer_(new char[rows * columns * kFieldBytes]) {
    cursor_ = buffer_.get();
  }

  void clear() { cursor_ = buffer_.get(); }
  void put(double v) {
    cursor_ = std::to_chars(cursor_, cursor_ + kFieldBytes, v).ptr;
    *cursor_++ = ',';
  }
  void put_6g(double v) {
    cursor_ = write_6g(cursor_, v);
    *cursor_++ = ',';
  }
  void put(std::uint64_t v) {
    cursor_ = std::to_chars(cursor_, cursor_ + kFieldBytes, v).ptr;
    *cursor_++ = ',';
  }
  void end_row() { cursor_[-1] = '\n'; }
  const char* data() const { return buffer_.get(); }
  std::size_t size() const { return static_cast<std::size_t>(cursor_ - buffer_.get()); }

 private:
  std::unique_ptr<char[]> buffer_;
  char* cursor_ = nullptr;
};

// The estimation loop stores each row's raw values into blocks; formatter
// threads format whole blocks and write them in their order. Formatting (about
// 20 numbers a row, 11 of them shortest round-trip) costs several steps of the
// estimator: with two formatters it spreads over both cores instead of one
// thread being the bottleneck while the estimation loop waits.
class RowPipeline {
 public:
  static constexpr std::size_t kRowsPerBlock = 2048;
  static constexpr std::size_t kBlocks = 6;
  static constexpr std::size_t kFormatters = 2;

  RowPipeline(AtomicFile& file, std::vector<ColumnFormat> formats)
      : file_(file), columns_(formats.size()), formats_(std::move(formats)) {
    storage_.resize(kBlocks);
    for (auto& b : storage_) {
      b.resize(kRowsPerBlock * columns_);
      free_.push_back(b.data());
    }
    current_ = free_.back();
    free_.pop_back();
    try {
      for (std::size_t i = 0; i < kFormatters; ++i) threads_.emplace_back([this] { run(); });
    } catch (...) {
      stop();
      throw;
    }
  }
  RowPipeline(const RowPipeline&) = delete;
  RowPipeline& operator=(const RowPipeline&) = delete;
  ~RowPipeline() { stop(); }

  // Where the next row's values go (columns() doubles).
  double* next_row() {
    if (used_ == kRowsPerBlock) hand_over();
    return current_ + columns_ * used_++;
  }
  // Everything formatted and written; rethrows a write error.
  void finish() {
    hand_over();
    stop();
    if (error_) std::rethrow_exception(error_);
  }

 private:
  struct Filled {
    double* rows;
    std::size_t count;
    std::uint64_t sequence;  // blocks are written in this order
  };

  void hand_over() {
    std::unique_lock<std::mutex> lock(mutex_);
    if (used_ > 0) {
      filled_.push_back({current_, used_, handed_over_++});
      filled_cv_.notify_one();
      free_cv_.wait(lock, [this] { return !free_.empty(); });
      current_ = free_.back();
      free_.pop_back();
      used_ = 0;
    }
  }

  void stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      done_ = true;
    }
    filled_cv_.notify_all();
    for (auto& t : threads_)
      if (t.joinable()) t.join();
  }

  void run() {
    RowWriter writer(kRowsPerBlock, columns_);
    for (;;) {
      Filled block{};
      {
        std::unique_lock<std::mutex> lock(mutex_);
        filled_cv_.wait(lock, [this] { return done_ || !filled_.empty(); });
        if (filled_.empty()) return;  // done and drained
        block = filled_.front();
        filled_.pop_front();
      }
      bool ok = !failed_.load();
      if (ok) format(block, writer);
      {
        std::lock_guard<std::mutex> lock(mutex_);
        free_.push_back(block.rows);
      }
      free_cv_.notify_one();
      // Write in block order: wait for the previous block's turn.
      std::unique_lock<std::mutex> lock(write_mutex_);
      write_cv_.wait(lock, [&] { return written_ == block.sequence; });
      if (ok && !failed_.load()) {
        try {
          file_.write(writer.data(), writer.size());
        } catch (...) {
          error_ = std::current_exception();  // read by finish() after the joins
          failed_ = true;
        }
      }
      ++written_;
      write_cv_.notify_all();
    }
  }

  void format(const Filled& block, RowWriter& writer) const {
    writer.clear();
    for (std::size_t r = 0; r < block.count; ++r) {
      const double* row = block.rows + r * columns_;
      for (std::size_t c = 0; c < columns_; ++c) {
        switch (formats_[c]) {
          case ColumnFormat::kExact:
            writer.put(row[c]);
            break;
          case ColumnFormat::kSixDigits:
            writer.put_6g(row[c]);
            break;
          case ColumnFormat::kInteger:
            writer.put(static_cast<std::uint64_t>(row[c]));
            break;
        }
      }
      writer.end_row();
    }
  }

  AtomicFile& file_;
  const std::size_t columns_;
  const std::vector<ColumnFormat> formats_;
  std::vector<std::vector<double>> storage_;
  double* current_ = nullptr;
  std::size_t used_ = 0;
  std::uint64_t handed_over_ = 0;

  std::mutex mutex_;
  std::condition_variable filled_cv_, free_cv_;
  std::deque<Filled> filled_;
  std::vector<double*> free_;
  bool done_ = false;

  std::mutex write_mutex_;  // the file and the order of the blocks in it
  std::condition_variable write_cv_;
  std::uint64_t written_ = 0;
  std::atomic<bool> failed_{false};
  std::exception_ptr error_;
  std::vector<std::thread> threads_;
};

// `\r[#####     ] 45% 1.2e6 samples/s` on stderr, at most 10 times a second,
// only when stderr is a terminal and the record's size is known. Done and total
// are in any unit; the rate is in samples.
class ProgressBar {
 public:
  ProgressBar(bool enabled, double total)
      : enabled_(enabled && total > 0.0 && ::isatty(2) == 1), total_(total), start_(Clock::now()), last_(start_) {}

  void maybe_draw(double done, std::uint64_t samples) {
    if (!enabled_) return;
    const auto now = Clock::now();
    if (now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    draw(done, samples, now);
  }
  void finish(std::uint64_t samples) {
    if (!enabled_ || !drawn_) return;
    draw(total_, samples, Clock::now());
    std::fputc('\n', stderr);
  }

 private:
  void draw(double done, std::uint64_t samples, Clock::time_point now) {
    constexpr int kWidth = 30;
    const double fraction = std::min(done / total_, 1.0);
    const int filled = static_cast<int>(fraction * kWidth);
    char bar[kWidth + 1];
    for (int i = 0; i < kWidth; ++i) bar[i] = i < filled ? '#' : ' ';
    bar[kWidth] = '\0';
    const double seconds = std::chrono::duration<double>(now - start_).count();
    const double rate = seconds > 0.0 ? static_cast<double>(samples) / seconds : 0.0;
    std::fprintf(stderr, "\r[%s] %3d%% %.2g samples/s ", bar, static_cast<int>(fraction * 100.0), rate);
    std::fflush(stderr);
    drawn_ = true;
  }

  bool enabled_;
  double total_;
  Clock::time_point start_, last_;
  bool drawn_ = false;
};

struct EstColumn {
  std::string name;
  ColumnFormat format;
};

std::vector<EstColumn> est_columns(const AdditiveModel& model) {
  std::vector<EstColumn> columns{{"t", ColumnFormat::kExact}};
  for (const auto& s : model.submodels) {
    for (const char* q : {"_wn", "_zeta", "_gain"}) columns.push_back({s.name + q, ColumnFormat::kExact});
    for (const char* q : {"_wn_std", "_zeta_std", "_gain_std"})
      columns.push_back({s.name + q, ColumnFormat::kSixDigits});
  }
  columns.push_back({"residual_rms", ColumnFormat::kExact});
  columns.push_back({"flags", ColumnFormat::kInteger});
  columns.push_back({"resets", ColumnFormat::kInteger});
  return columns;
}

// The daemon's fault detector over the record, run as the daemon runs it: an
// update at the first sample at or past each publish time, on the sample times
// as the daemon's whole microseconds (utime), the estimates' covariances, valid
// outside warm-up and low excitation. The daemon runs the warm-up fit on
// another thread: at the sample that completes the window it still reports the
// warm-up (the fit's update is not valid there) and steps the samples held
// meanwhile afterwards, as track does. Each flag change becomes a row of the
// flags CSV: t,mode,quantity,event,value,baseline,relative,sigma.
class FlagRecorder {
 public:
  FlagRecorder(const Config& config, const RecursiveEstimator& estimator)
      : detector_(fault_detector_settings(config)),
        input_(estimator),
        names_(detector_.status().size()),
        period_us_(std::max<std::int64_t>(1, std::llround(config.daemon.publish_period * 1e6))) {
    for (std::size_t i = 0; i < names_.size(); ++i) names_[i] = config.model.submodels[i].name;
    changes_.reserve(kQuantities * names_.size());
  }

  // After the estimator's step on the sample at t (s).
  void after_step(double t, const RecursiveEstimator& estimator) {
    const EstimatorStatus& st = estimator.status();
    // A refit runs within one step() here, where the daemon's fitter holds the
    // input: the sample that ends a window counts as a warm-up sample either way.
    const bool fit_sample = input_.fitted_in_step(st);
    const std::int64_t utime = std::llround(t * 1e6);
    if (!have_time_) {
      have_time_ = true;
      utime0_ = utime;
      next_publish_ = utime + period_us_;
    } else if (utime <= last_utime_) {
      return;  // the daemon drops a sample that is not later than the last
    }
    last_utime_ = utime;
    if (utime < next_publish_) return;
    next_publish_ += period_us_;
    if (next_publish_ <= utime) next_publish_ = utime + period_us_;
    input_.read(estimator);
    changes_.clear();
    const bool valid = !fit_sample && st.estimates_measure_plant();
    input_.update(detector_, static_cast<double>(utime - utime0_) * 1e-6, valid, changes_);
    for (const FlagChange& c : changes_) {
      static constexpr const char* kQuantityNames[kQuantities] = {"wn", "zeta", "gain"};
      char line[256];
      std::snprintf(line, sizeof line, "%.17g,%s,%s,%s,%.17g,%.17g,%.17g,%.17g\n", t,
                    names_[static_cast<std::size_t>(c.mode)].c_str(), kQuantityNames[static_cast<int>(c.quantity)],
                    c.raised ? "raised" : "cleared", c.value, c.baseline, c.deviation_relative, c.deviation_sigma);
      rows_ += line;
      ++(c.raised ? raised_ : cleared_);
    }
  }

  const std::string& rows() const { return rows_; }
  int raised() const { return raised_; }
  int cleared() const { return cleared_; }
  const FaultDetector& detector() const { return detector_; }

 private:
  FaultDetector detector_;
  DetectorInput input_;
  std::vector<std::string> names_;
  std::vector<FlagChange> changes_;
  std::int64_t period_us_, utime0_ = 0, last_utime_ = 0, next_publish_ = 0;
  bool have_time_ = false;
  std::string rows_;
  int raised_ = 0, cleared_ = 0;
};

double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

}  // namespace

int track(const TrackArgs& args) {
  return guarded("track", [&] {
    const auto t_start = Clock::now();
    const Config config = load_config(args.config);
    if (config.model.submodels.empty())
      throw InputError(args.config, "model gives only modes: N; track needs the submodels (fit --out writes them)");
    const EstimatorSettings& settings = config.estimator;  // completed by load_config

    RecordReadOptions read_options;
    read_options.allow_nonfinite = true;
    read_options.allow_gaps = true;
    read_options.sample_time = config.sample_time;
    const RecordSource source(args.data, model_record_columns(args.columns, config.model, config.closed_loop),
                              args.channel, config.closed_loop);
    // A CSV's header and columns checked here (an LCM log read whole).
    RecordReader reader_source = naming_column_options(source, [&] { return RecordReader(source, read_options); });
    const bool with_r = reader_source.has_reference();
    if (config.closed_loop && !with_r) throw InputError(args.data, "closed loop (model.loop) needs a column 'r'");
    RecordCheck check(args.data, config.sample_time, config.closed_loop, config.source);
    const auto t_read = Clock::now();

    RecursiveEstimator estimator(config.model, settings);
    const int K = estimator.submodels();
    const std::vector<EstColumn> columns = est_columns(config.model);

    AtomicFile file(args.out);
    std::optional<AtomicFile> flags_file;
    std::optional<FlagRecorder> recorder;
    if (!args.faults.empty()) {
      flags_file.emplace(args.faults);
      recorder.emplace(config, estimator);
    }
    {
      std::string header;
      for (const auto& c : columns) (header += header.empty() ? "" : ",") += c.name;
      header += '\n';
      file.write(header.data(), header.size());
    }

    std::uint64_t n = 0;
    double last_t = 0.0;
    // One sample, filled in place (its further inputs, with several, from the block's further_u).
    Sample sample;
    sample.further_inputs = config.model.n_inputs() - 1;
    ProgressBar progress(args.progress && reader_source.fraction_read().has_value(), 1.0);
    std::vector<ColumnFormat> formats;
    for (const auto& c : columns) formats.push_back(c.format);
    RowPipeline rows(file, std::move(formats));
    {
      BlockReader reader(reader_source);
      while (const Record* block = reader.next()) {
        check.add(*block);  // a wrong sample_rate_hz fails on the first block
        const std::size_t count = static_cast<std::size_t>(block->size());
        const double *t = block->t.data(), *u = block->u.data(), *y = block->y.data();
        const double* r = with_r ? block->r.data() : nullptr;
        // One row of estimates per sample.
        for (std::size_t k = 0; k < count; ++k) {
          sample.t = t[k];
          sample.u = u[k];
          sample.y = y[k];
          sample.r = r != nullptr ? r[k] : 0.0;
          for (int j = 0; j < sample.further_inputs; ++j)
            sample.further_u[static_cast<std::size_t>(j)] =
                block->further_u[static_cast<std::size_t>(j)](static_cast<Eigen::Index>(k));
          const unsigned flags = estimator.step(sample);
          double* row = rows.next_row();
          *row++ = t[k];
          for (int m = 0; m < K; ++m) {
            const ModeEstimate e = estimator.mode(m);
            row[0] = e.value.wn;
            row[1] = e.value.zeta;
            row[2] = e.value.gain;
            row[3] = e.std.wn;
            row[4] = e.std.zeta;
            row[5] = e.std.gain;
            row += 6;
          }
          row[0] = estimator.residual_rms();
          row[1] = static_cast<double>(flags);
          row[2] = static_cast<double>(estimator.status().resets);
          if (recorder) recorder->after_step(t[k], estimator);
        }
        n += count;
        if (count > 0) last_t = t[count - 1];
        progress.maybe_draw(reader.fraction_read(), n);
      }
    }
    check.finish(source, read_options);  // nothing written on failure: the temporary file goes
    rows.finish();
    if (recorder) {
      flags_file->write("t,mode,quantity,event,value,baseline,relative,sigma\n");
      flags_file->write(recorder->rows());
    }
    file.commit();
    if (flags_file) flags_file->commit();
    progress.finish(n);
    const auto t_end = Clock::now();

    // Summary (stderr) and the final modal table (stdout).
    const EstimatorStatus& st = estimator.status();
    const double total = seconds_between(t_start, t_end), loop = seconds_between(t_read, t_end);
    std::string inputs_text;
    if (config.model.n_inputs() > 1) {
      inputs_text = ", inputs";
      for (const std::string& name : config.model.inputs) inputs_text += " " + name;
    }
    std::fprintf(stderr, "modalwatch track: %llu samples at %g Hz (%s loop, %d submodels%s, output hold %s%s) -> %s\n",
                 static_cast<unsigned long long>(n), 1.0 / config.sample_time, config.closed_loop ? "closed" : "open",
                 K, inputs_text.c_str(), hold_name(config.estimator.output_hold),
                 config.output_hold ? "" : " by default", args.out.c_str());
    std::fprintf(stderr, "  time: %.3f s (start-up %.3f s, then read, estimate and write together %.3f s)\n", total,
                 seconds_between(t_start, t_read), loop);
    std::fprintf(stderr, "  samples/s: %.4g end to end, %.4g after start-up\n",
                 total > 0.0 ? static_cast<double>(n) / total : 0.0, loop > 0.0 ? static_cast<double>(n) / loop : 0.0);
    if (recorder) {
      std::fprintf(stderr, "  flags: %d raised, %d cleared -> %s\n", recorder->raised(), recorder->cleared(),
                   args.faults.c_str());
      for (std::size_t i = 0; i < recorder->detector().status().size(); ++i) {
        const ModeStatus& m = recorder->detector().status()[i];
        static constexpr const char* kStates[] = {"learning", "ready", "configured"};
        std::fprintf(stderr, "    %s: baseline %s", config.model.submodels[i].name.c_str(),
                     kStates[static_cast<int>(m.state)]);
        static constexpr const char* kHolds[] = {"none", "an estimate too uncertain", "the estimate drifting"};
        if (m.baseline_ready)
          std::fprintf(stderr, " (wn %.6g, zeta %.4g, gain %.6g)", m.baseline.value.wn, m.baseline.value.zeta,
                       m.baseline.value.gain);
        else if (m.learn_restarts > 0)
          std::fprintf(stderr, " (%d windows restarted, the last for %s)", m.learn_restarts,
                       kHolds[static_cast<int>(m.learn_hold)]);
        std::fprintf(stderr, "\n");
      }
    }
    std::fprintf(stderr, "  samples processed: %llu\n", static_cast<unsigned long long>(st.samples));
    std::fprintf(stderr, "  updates: %llu\n", static_cast<unsigned long long>(st.updates));
    if (st.resets > 0)
      std::fprintf(stderr, "  resets: %llu (last: %s)\n", static_cast<unsigned long long>(st.resets),
                   st.last_reset_reason);
    else
      std::fprintf(stderr, "  resets: 0\n");
    std::fprintf(stderr, "  covariance boosts on a change: %llu\n", static_cast<unsigned long long>(st.boosts));
    std::fprintf(stderr, "  noise level changes (no submodel explains the error): %llu\n",
                 static_cast<unsigned long long>(st.noise_changes));
    std::fprintf(stderr, "  modes restored after a sign change of their gain: %llu\n",
                 static_cast<unsigned long long>(st.sign_restores));
    std::fprintf(stderr, "  rejected non-finite: %llu\n", static_cast<unsigned long long>(st.rejected_nonfinite));
    std::fprintf(stderr, "  rejected out-of-order: %llu\n", static_cast<unsigned long long>(st.rejected_out_of_order));
    std::fprintf(stderr, "  gaps: %llu\n", static_cast<unsigned long long>(st.gaps));
    std::fprintf(stderr, "  outliers: %llu\n", static_cast<unsigned long long>(st.outliers));
    std::fprintf(stderr, "  low-excitation samples: %llu\n",
                 static_cast<unsigned long long>(st.low_excitation_samples));
    std::fprintf(stderr, "  projections: %llu\n", static_cast<unsigned long long>(st.projections));
    std::fprintf(stderr, "  covariance clamps: %llu\n", static_cast<unsigned long long>(st.covariance_clamps));
    if (settings.warmup_samples <= 0)
      std::fprintf(stderr, "  warm-up fit: none (no warm-up window; initial model from %s)\n", config.source.c_str());
    else if (st.warming_up)
      std::fprintf(stderr, "  warm-up fit: not reached (record shorter than the %d-sample warm-up window)\n",
                   settings.warmup_samples);
    else if (st.warmup_fit_used)
      std::fprintf(stderr, "  warm-up fit: used (%d samples)\n", settings.warmup_samples);
    else
      std::fprintf(stderr, "  warm-up fit: not used (%s; initial model from %s)\n",
                   settings.fit_on_warmup ? kWarmupFitNotUsed : "fit_on_warmup is off", config.source.c_str());

    std::printf("modalwatch track: %llu samples, final estimate at t = %.6g s\n", static_cast<unsigned long long>(n),
                last_t);
    {
      std::vector<Eigen::MatrixXd> covariances;
      for (int i = 0; i < estimator.submodels(); ++i) {
        const int nt = estimator.submodel(i).n_theta();
        covariances.push_back(estimator.status().warming_up ? Eigen::MatrixXd::Zero(nt, nt) : estimator.covariance(i));
      }
      print_modal_table(estimator.model(), covariances);
    }
    std::printf("\nresidual RMS: %.4g\n", estimator.residual_rms());
    return 0;
  });
}

}  // namespace modalwatch::cli
