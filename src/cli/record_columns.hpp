#pragma once
// The CSV columns the commands (fit, diagnose, track, replay) read as t, u and
// y, chosen with --t-column, --u-column and --y-column, and the readers that
// name those options when a record lacks the column. --u-column may be
// repeated: several measured inputs, in order.
#include <algorithm>
#include <string>
#include <vector>

#include "modalwatch/error.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/io/records.hpp"
#include "modalwatch/model.hpp"

namespace modalwatch::cli {

struct ColumnArgs {
  std::string t = "t", y = "y";  // e.g. n (sample index), y2
  std::vector<std::string> u;    // e.g. u1, u2; none given: model.inputs, else u
};

// The input columns: --u-column, else the model's inputs, else u. A model of
// several inputs needs as many columns (taken in its order), a closed loop has one.
inline std::vector<std::string> input_columns(const ColumnArgs& args, const AdditiveModel& model, bool closed_loop) {
  const std::vector<std::string> names = !args.u.empty()         ? args.u
                                         : !model.inputs.empty() ? model.inputs
                                                                 : std::vector<std::string>{"u"};
  if (closed_loop && names.size() > 1)
    throw InputError("--u-column", "a closed loop has one input (the controller's u); several inputs need loop: open");
  if (static_cast<int>(names.size()) < model.n_inputs())
    throw InputError("--u-column", "the model has " + std::to_string(model.n_inputs()) +
                                       " inputs (model.inputs); name as many input columns");
  return names;
}

inline RecordColumns record_columns(const ColumnArgs& args, const std::vector<std::string>& inputs) {
  RecordColumns columns;
  columns.t = args.t;
  columns.u = inputs.front();
  columns.further_u.assign(inputs.begin() + 1, inputs.end());
  columns.y = args.y;
  return columns;
}

// The columns for a command that runs the model as configured (track, and
// replay for the daemon): exactly its inputs, no more.
inline RecordColumns model_record_columns(const ColumnArgs& args, const AdditiveModel& model, bool closed_loop) {
  const std::vector<std::string> inputs = input_columns(args, model, closed_loop);
  if (static_cast<int>(inputs.size()) != model.n_inputs())
    throw InputError("--u-column", "names " + std::to_string(inputs.size()) + " input columns, the model has " +
                                       std::to_string(model.n_inputs()) + " input" +
                                       (model.n_inputs() > 1 ? "s (model.inputs)" : ""));
  return record_columns(args, inputs);
}

// A record without a sample rate: its time column, named otherwise than t, counts
// samples (whole numbers one apart, as sample_rate_hz: 1 checks), and its
// frequencies are in cycles/sample rather than Hz.
inline bool time_in_samples(const Record& r, const ColumnArgs& columns, double sample_time) {
  if (columns.t == "t" || sample_time != 1.0) return false;
  return (r.t.array() == r.t.array().round()).all();
}

inline const char* frequency_unit(bool in_samples) { return in_samples ? "cycles/sample" : "Hz"; }

// read(): reads from `source` (read_record, a RecordReader), with a missing
// column named with the option that picks another.
template <class Read>
auto naming_column_options(const RecordSource& source, Read&& read) {
  try {
    return read();
  } catch (const MissingColumnError& e) {
    const auto& further = source.columns.further_u;
    const bool input =
        e.column() == source.columns.u || std::find(further.begin(), further.end(), e.column()) != further.end();
    const char* option = e.column() == source.columns.t   ? "--t-column"
                         : input                          ? "--u-column"
                         : e.column() == source.columns.y ? "--y-column"
                                                          : nullptr;
    if (!option) throw;
    std::string message = e.what();
    if (!e.location().empty() && message.starts_with(e.location() + ": "))
      message.erase(0, e.location().size() + 2);
    throw InputError(e.location(), message + "; pick one with " + option);
  }
}

inline Record read_record_with_columns(const RecordSource& source) {
  return naming_column_options(source, [&] { return read_record(source); });
}

}  // namespace modalwatch::cli
