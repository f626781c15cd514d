#include "records.hpp"

#include <cmath>
#include <cstdio>

#include "modalwatch/error.hpp"
#include "modalwatch/io/lcm_log.hpp"

namespace modalwatch::cli {

namespace {

void check_csv_source(const RecordSource& source) {
  if (!source.channel.empty())
    throw InputError("--channel", "applies to LCM logs only; " + source.path + " is not one (no LCM sync word)");
}

}  // namespace

std::optional<RecordStream> open_csv_stream(const RecordSource& source, const RecordReadOptions& options) {
  if (is_lcm_log(source.path)) return std::nullopt;
  check_csv_source(source);
  return RecordStream(source.path, source.columns, options);
}

Record load_record(const RecordSource& source, const RecordReadOptions& options) {
  if (!is_lcm_log(source.path)) {
    check_csv_source(source);
    return read_record(source.path, source.columns, options);
  }
  const RecordColumns csv_default;
  if (source.columns.t != csv_default.t || source.columns.u != csv_default.u || source.columns.y != csv_default.y ||
      source.columns.r != csv_default.r)
    throw InputError(source.path, "LCM log: column options apply to CSV records only (an LCM log has u, y, r)");
  LcmLogOptions lo;
  lo.channel = source.channel;
  lo.closed_loop = source.closed_loop;
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
    for (Eigen::Index k = 0; k < rec.size(); ++k)
      if (!std::isfinite(rec.u(k)) || !std::isfinite(rec.y(k)) || (rec.has_reference() && !std::isfinite(rec.r(k))))
        throw InputError(source.path, where(k) + ": NaN or Inf in u, y or r");
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
  std::fprintf(stderr, "modalwatch: %lld samples from LCM log %s (channel %s; %llu events, skipped: %llu other channel, "
                       "%llu other type, %llu invalid, %llu samples out of order or duplicate)\n",
               static_cast<long long>(n), source.path.c_str(), log.channels.front().c_str(),
               static_cast<unsigned long long>(log.events), static_cast<unsigned long long>(log.skipped_channel),
               static_cast<unsigned long long>(log.skipped_type), static_cast<unsigned long long>(log.skipped_invalid),
               static_cast<unsigned long long>(log.skipped_order));
  return rec;
}

Table read_signal_file(const std::string& path, const std::string& channel) {
  if (!is_lcm_log(path)) {
    if (!channel.empty()) throw InputError(path, "key 'channel' applies to LCM logs only; this is not one (no LCM sync word)");
    return read_table(path);
  }
  RecordSource source;
  source.path = path;
  source.channel = channel;
  source.closed_loop = true;
  RecordReadOptions options;
  options.allow_gaps = true;
  const Record rec = load_record(source, options);
  Table table;
  table.columns = {"t", "u", "y", "r"};
  table.data.resize(rec.size(), 4);
  table.data.col(0) = rec.t;
  table.data.col(1) = rec.u;
  table.data.col(2) = rec.y;
  table.data.col(3) = rec.r;
  return table;
}

}  // namespace modalwatch::cli
