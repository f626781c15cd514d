// The daemon and `track --faults` on records of the scenario bank: the same
// samples, sent over LCM to the daemon and read by `track` from a file, give
// the same flag changes to the microsecond. The bank is generated outside the
// test (scripts/check/scenario_bank_small.sh, which runs this test with
// MODALWATCH_BANK_DIR set); without it the test skips.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "daemon_support.hpp"

using namespace modalwatch;
using namespace modalwatch::test_support;

namespace {

class DaemonOnBankRecords : public ScratchDir {};

// The first `count` fault records of the bank (directories named <id>-<class>-...).
std::vector<std::filesystem::path> fault_records(const std::string& bank, std::size_t count) {
  std::vector<std::filesystem::path> all;
  for (const auto& e : std::filesystem::directory_iterator(bank))
    if (e.is_directory() && std::filesystem::exists(e.path() / "record.csv") &&
        e.path().filename().string().find("-healthy-") == std::string::npos)
      all.push_back(e.path());
  std::sort(all.begin(), all.end());
  if (all.size() > count) all.resize(count);
  return all;
}

}  // namespace

TEST_F(DaemonOnBankRecords, FlagChangesAreThoseOfTrackOnThreeFaultRecords) {
  const char* bank = std::getenv("MODALWATCH_BANK_DIR");
  if (!bank)
    GTEST_SKIP() << "MODALWATCH_BANK_DIR not set: scripts/check/scenario_bank_small.sh runs this test on a "
                    "generated bank";
  const auto records = fault_records(bank, 3);
  ASSERT_EQ(records.size(), 3u) << "the bank in " << bank << " has fewer than three fault records";
  std::size_t flagged = 0;
  for (const auto& dir : records) {
    SCOPED_TRACE(dir.filename().string());
    const std::string config_path = (dir / "config.yaml").string();
    const Config c = load_config(config_path);
    const Record rec = read_record((dir / "record.csv").string());

    Received rx;
    const DaemonCounters k = run_in_process(c, rec, rx, 120.0);
    EXPECT_EQ(k.samples_processed, static_cast<std::uint64_t>(rec.size()));
    EXPECT_EQ(k.samples_dropped + k.decode_errors + k.samples_nonfinite + k.gaps, 0u);

    const std::string csv = path(dir.filename().string() + ".csv"), flags = path(dir.filename().string() + ".flags");
    write_wire_times_csv(rec, csv);
    const Outcome tr = run_cli("track --no-progress --config " + config_path + " --data " + csv + " --out " +
                               path("est.csv") + " --faults " + flags);
    ASSERT_EQ(tr.code, 0) << tr.output;
    const std::vector<std::string> daemon = daemon_flag_changes(rx.status, std::llround(rec.t(0) * 1e6));
    EXPECT_EQ(track_flag_changes(flags), daemon) << "track --faults and the daemon flag differently";
    flagged += !daemon.empty();
  }
  // The identity is only worth something where flags change.
  EXPECT_GE(flagged, 1u);
}
