#pragma once
// `fit --max-modes`: the number of modes chosen from the data (model_order.hpp),
// its table on stdout, and the stabilisation diagram's tables in a directory
// (stabilisation.csv: per order its BIC and each mode found, with the stability
// marks; frf.csv: the measured frequency response with its coherence beside the
// chosen model's; summary.json), drawn over the measured response by
// scripts/plot/plot_stabilisation.py.
#include <string>

#include "modalwatch/model_order.hpp"
#include "modalwatch/record.hpp"

namespace modalwatch::cli {

// One line per order: modes asked, BIC, fit %, converged, the modes found (a
// star for stable in frequency and damping, a dot for stable in frequency).
void print_order_selection(const OrderSelection& selection, bool in_samples);

// Writes dir/stabilisation.csv, dir/frf.csv and dir/summary.json (per order
// its BIC, fit and convergence; the chosen number of modes; the unit of time,
// "s" or "samples"), dir created, then runs plot_script on dir when given.
void write_stabilisation(const std::string& dir, const OrderSelection& selection, const Record& data, bool closed_loop,
                         bool in_samples, const std::string& plot_script);

}  // namespace modalwatch::cli
