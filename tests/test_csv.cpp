// CSV records: parsing, the errors (row and column named), atomic writing, and
// the shared measured records read in place.
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "support.hpp"

#include "modalwatch/error.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/io/records.hpp"

namespace fs = std::filesystem;
using modalwatch::InputError;
using modalwatch::parse_record;
using modalwatch::parse_table;
using modalwatch::read_record;
using modalwatch::read_table;

namespace {

#define EXPECT_CONTAINS(text, part) EXPECT_NE(std::string(text).find(part), std::string::npos) << "message: " << (text)

using modalwatch::test_support::error_of;

class CsvTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::random_device rd;
    dir_ = fs::temp_directory_path() / ("modalwatch-csv-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string file(const std::string& name, const std::string& content) const {
    const std::string path = (dir_ / name).string();
    std::ofstream(path, std::ios::binary) << content;
    return path;
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  // Files in the directory, to check that writes leave no temporaries.
  int entries() const {
    return static_cast<int>(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()));
  }

  fs::path dir_;
};

TEST_F(CsvTest, ReadsHeaderAndNumbers) {
  const auto p = file("a.csv", " t , u,y \n0,1.5,-2\n0.1,+3e-2,4E1\n");
  const auto table = read_table(p);
  ASSERT_EQ(table.columns, (std::vector<std::string>{"t", "u", "y"}));
  ASSERT_EQ(table.data.rows(), 2);
  EXPECT_EQ(table.data(0, 1), 1.5);
  EXPECT_EQ(table.data(0, 2), -2.0);
  EXPECT_EQ(table.data(1, 1), 0.03);
  EXPECT_EQ(table.data(1, 2), 40.0);
  EXPECT_EQ(table.column("y"), 2);
  EXPECT_EQ(table.column("r"), -1);
}

TEST_F(CsvTest, AcceptsCrLfMissingFinalNewlineAndTrailingBlankLines) {
  EXPECT_EQ(read_table(file("crlf.csv", "t,u,y\r\n0,1,2\r\n1,3,4\r\n")).data(1, 2), 4.0);
  EXPECT_EQ(read_table(file("nofinal.csv", "t,u,y\n0,1,2\n1,3,4")).data.rows(), 2);
  EXPECT_EQ(read_table(file("blank.csv", "t,u,y\n0,1,2\n1,3,4\n\n  \n")).data.rows(), 2);
}

TEST_F(CsvTest, NonNumericFieldNamesRowAndColumn) {
  const auto p = file("bad.csv", "t,u,y\n0,1,2\n0.1,abc,3\n");
  const auto msg = error_of([&] { read_table(p); });
  EXPECT_CONTAINS(msg, p + ": row 3, column 'u'");
  EXPECT_CONTAINS(msg, "not a number (got 'abc')");
}

TEST_F(CsvTest, TrailingGarbageInFieldIsRejected) {
  const auto msg = error_of([&] { read_table(file("g.csv", "t,u,y\n0,1.5x,2\n")); });
  EXPECT_CONTAINS(msg, "row 2, column 'u'");
  EXPECT_CONTAINS(msg, "1.5x");
  EXPECT_CONTAINS(error_of([&] { read_table(file("h.csv", "t,u,y\n0,0x10,2\n")); }), "row 2, column 'u'");
}

TEST_F(CsvTest, NanAndInfAreRejected) {
  for (const std::string bad : {"nan", "NaN", "inf", "-inf", "Infinity", "1e999"}) {
    const auto p = file("n.csv", "t,u,y\n0,1,2\n0.1,2,3\n0.2,4," + bad + "\n");
    const auto msg = error_of([&] { read_table(p); });
    EXPECT_CONTAINS(msg, "row 4, column 'y'");
    EXPECT_CONTAINS(msg, bad);
  }
}

TEST_F(CsvTest, EmptyFieldIsRejected) {
  const auto msg = error_of([&] { read_table(file("e.csv", "t,u,y\n0,,2\n")); });
  EXPECT_CONTAINS(msg, "row 2, column 'u'");
  EXPECT_CONTAINS(msg, "empty field");
}

TEST_F(CsvTest, ShortRowNamesFirstMissingColumn) {
  const auto msg = error_of([&] { read_table(file("s.csv", "t,u,y\n0,1,2\n0.1,2\n")); });
  EXPECT_CONTAINS(msg, "row 3, column 'y'");
  EXPECT_CONTAINS(msg, "row has 2 fields, header has 3");
}

TEST_F(CsvTest, LongRowIsRejected) {
  const auto msg = error_of([&] { read_table(file("l.csv", "t,u,y\n0,1,2\n0.1,2,3,4\n")); });
  EXPECT_CONTAINS(msg, "row 3");
  EXPECT_CONTAINS(msg, "row has 4 fields, header has 3");
}

TEST_F(CsvTest, EmptyFileHeaderOnlyAndBadHeader) {
  EXPECT_CONTAINS(error_of([&] { read_table(file("empty.csv", "")); }), "empty file");
  EXPECT_CONTAINS(error_of([&] { read_table(file("ws.csv", " \n\n")); }), "empty file");
  EXPECT_CONTAINS(error_of([&] { read_table(file("h.csv", "t,u,y\n")); }), "no data rows");
  const auto dup = error_of([&] { read_table(file("d.csv", "t,u,u\n0,1,2\n")); });
  EXPECT_CONTAINS(dup, "row 1, column 'u'");
  EXPECT_CONTAINS(dup, "duplicate column name");
  EXPECT_CONTAINS(error_of([&] { read_table(file("x.csv", "t,,y\n0,1,2\n")); }), "empty column name");
}

TEST_F(CsvTest, BlankLineBetweenRowsIsRejected) {
  const auto msg = error_of([&] { read_table(file("b.csv", "t,u,y\n0,1,2\n\n1,3,4\n")); });
  EXPECT_CONTAINS(msg, "row 3");
  EXPECT_CONTAINS(msg, "empty row");
}

TEST_F(CsvTest, MissingFileNamesPath) {
  const auto p = path("nope.csv");
  const auto msg = error_of([&] { read_table(p); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "cannot open");
}

TEST_F(CsvTest, ReadRecordWithAndWithoutReference) {
  const auto open = read_record(file("o.csv", "t,u,y,extra\n0,1,2,9\n0.5,3,4,9\n1,5,6,9\n"));
  EXPECT_EQ(open.size(), 3);
  EXPECT_FALSE(open.has_reference());
  EXPECT_EQ(open.u(1), 3.0);
  EXPECT_EQ(open.y(2), 6.0);
  EXPECT_DOUBLE_EQ(open.sample_time(), 0.5);

  const auto closed = read_record(file("c.csv", "y,r,u,t\n2,7,1,0\n4,8,3,0.5\n"));
  ASSERT_TRUE(closed.has_reference());
  EXPECT_EQ(closed.r(1), 8.0);
  EXPECT_EQ(closed.t(1), 0.5);
  EXPECT_EQ(closed.u(1), 3.0);
}

TEST_F(CsvTest, ReadRecordWithOtherColumnNames) {
  modalwatch::RecordColumns cols;
  cols.t = "time";
  cols.u = "voltage";
  cols.y = "position";
  const auto rec = read_record({file("n.csv", "time,voltage,position\n0,1,2\n1,3,4\n"), cols});
  EXPECT_EQ(rec.y(1), 4.0);
}

TEST_F(CsvTest, MissingColumnIsNamedWithAvailableOnes) {
  const auto msg = error_of([&] { read_record(file("m.csv", "t,u,force\n0,1,2\n1,3,4\n")); });
  EXPECT_CONTAINS(msg, "missing column 'y'");
  EXPECT_CONTAINS(msg, "available: t, u, force");
}

TEST_F(CsvTest, NonIncreasingTimeNamesRowAndColumn) {
  const auto back = error_of([&] { read_record(file("t.csv", "t,u,y\n0,1,2\n1,1,2\n0.5,1,2\n")); });
  EXPECT_CONTAINS(back, "row 4, column 't'");
  EXPECT_CONTAINS(back, "does not increase");
  const auto equal = error_of([&] { read_record(file("e.csv", "t,u,y\n0,1,2\n1,1,2\n1,1,2\n")); });
  EXPECT_CONTAINS(equal, "row 4, column 't'");
}

TEST_F(CsvTest, UnevenSamplingNamesRow) {
  // Steps of 1 s and one of 1.1 s (t = 6.1, row 8): the mean is 1.01 s, so only
  // the long step is off by more than 1 %.
  const auto msg = error_of([&] {
    read_record(file("u.csv",
                     "t,u,y\n0,0,0\n1,0,0\n2,0,0\n3,0,0\n4,0,0\n5,0,0\n6.1,0,0\n7.1,0,0\n"
                     "8.1,0,0\n9.1,0,0\n10.1,0,0\n"));
  });
  EXPECT_CONTAINS(msg, "row 8, column 't'");
  EXPECT_CONTAINS(msg, "uneven sampling");
  // Jitter well inside 1 % is accepted.
  EXPECT_NO_THROW(read_record(file("j.csv", "t,u,y\n0,0,0\n1.001,0,0\n2,0,0\n2.999,0,0\n")));
}

TEST_F(CsvTest, ReadOptionsAllowNonFiniteSamplesButNotTime) {
  modalwatch::RecordReadOptions options;
  options.allow_nonfinite = true;
  const auto p = file("nan.csv", "t,u,y,r\n0,nan,1,2\n1,1,inf,-inf\n2,1,2,3\n");
  const auto rec = read_record(p, options);
  EXPECT_TRUE(std::isnan(rec.u(0)));
  EXPECT_TRUE(std::isinf(rec.y(1)));
  EXPECT_TRUE(std::isinf(rec.r(1)));
  EXPECT_CONTAINS(error_of([&] { read_record(p); }), "row 2, column 'u'");  // default: rejected
  const auto bad_t = file("nant.csv", "t,u,y\n0,1,1\nnan,1,1\n");
  EXPECT_CONTAINS(error_of([&] { read_record(bad_t, options); }), "row 3, column 't'");
  // Non-numeric text stays an error.
  EXPECT_CONTAINS(error_of([&] { read_record(file("txt.csv", "t,u,y\n0,x,1\n"), options); }), "row 2, column 'u'");
}

TEST_F(CsvTest, ReadOptionsAllowGaps) {
  modalwatch::RecordReadOptions options;
  options.allow_gaps = true;
  // A gap of 3 steps after t = 2 (row 4 -> row 5), otherwise steps of 1.
  const auto p = file("gap.csv", "t,u,y\n0,0,0\n1,0,0\n2,0,0\n5,0,0\n6,0,0\n7,0,0\n");
  EXPECT_EQ(read_record(p, options).size(), 6);
  EXPECT_CONTAINS(error_of([&] { read_record(p); }), "uneven sampling");
  // A step shorter than the nominal one is still an error, with the median or a given step.
  const auto short_step = file("short.csv", "t,u,y\n0,0,0\n1,0,0\n1.5,0,0\n2.5,0,0\n3.5,0,0\n");
  const auto msg = error_of([&] { read_record(short_step, options); });
  EXPECT_CONTAINS(msg, "row 4, column 't'");
  EXPECT_CONTAINS(msg, "shorter than the nominal step 1 ");
  options.sample_time = 2.0;
  EXPECT_CONTAINS(error_of([&] { read_record(p, options); }), "row 3, column 't'");
  // Time must still increase.
  options.sample_time = 0.0;
  EXPECT_CONTAINS(error_of([&] { read_record(file("dec.csv", "t,u,y\n0,0,0\n1,0,0\n1,0,0\n"), options); }),
                  "does not increase");
}

TEST_F(CsvTest, WriteRecordRoundTripsExactly) {
  modalwatch::Record rec;
  rec.t = Eigen::VectorXd::LinSpaced(5, 0.0, 0.4);
  rec.u = Eigen::VectorXd::Random(5);
  rec.y = Eigen::VectorXd::Random(5) * 1e-7;
  rec.y(3) = 1.0 / 3.0;
  const auto p = path("rec.csv");
  modalwatch::write_record(p, rec);
  EXPECT_EQ(entries(), 1);  // no temporary left behind
  std::ifstream in(p);
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header, "t,u,y");
  const auto back = read_record(p);
  EXPECT_EQ(back.t, rec.t);
  EXPECT_EQ(back.u, rec.u);
  EXPECT_EQ(back.y, rec.y);
  EXPECT_FALSE(back.has_reference());

  rec.r = Eigen::VectorXd::Random(5);
  modalwatch::write_record(p, rec);  // replaces the file
  std::ifstream in2(p);
  std::getline(in2, header);
  EXPECT_EQ(header, "t,r,u,y");
  EXPECT_EQ(read_record(p).r, rec.r);
}

TEST_F(CsvTest, WriteTableRoundTripsLargeTable) {
  const Eigen::Index n = 200000;
  Eigen::MatrixXd data(n, 3);
  data.col(0) = Eigen::VectorXd::LinSpaced(n, 0.0, static_cast<double>(n - 1) * 1e-3);
  data.rightCols(2).setRandom();
  const auto p = path("big.csv");
  modalwatch::write_table(p, {"t", "a", "b"}, data);
  const auto table = read_table(p);
  EXPECT_EQ(table.data, data);
}

TEST_F(CsvTest, WriteFailureThrowsAndLeavesNothing) {
  const auto p = (dir_ / "no-such-dir" / "x.csv").string();
  const auto msg = error_of([&] { modalwatch::write_table(p, {"a"}, Eigen::MatrixXd::Zero(2, 1)); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_EQ(entries(), 0);
  // Renaming onto a directory fails after the temporary was written: it is removed.
  fs::create_directory(dir_ / "adir");
  const auto onto_dir = (dir_ / "adir").string();
  EXPECT_CONTAINS(error_of([&] { modalwatch::write_table(onto_dir, {"a"}, Eigen::MatrixXd::Zero(2, 1)); }), onto_dir);
  EXPECT_EQ(entries(), 1);
  EXPECT_CONTAINS(error_of([&] {
                    modalwatch::write_table(path("y.csv"), {"a", "b"}, Eigen::MatrixXd::Zero(2, 1));
                  }),
                  "2 column names for 1 columns");
  EXPECT_CONTAINS(error_of([&] { modalwatch::write_table(path("y.csv"), {"a,b"}, Eigen::MatrixXd::Zero(2, 1)); }),
                  "invalid column name");
  EXPECT_EQ(entries(), 1);
}

// ---------------------------------------------------------------- shared data

// Its read time is a benchmark's figure, not a test's: it depends on the machine's load.
TEST(CsvShared, SilverboxHasEveryRowAndItsSampleTime) {
  const auto p = modalwatch::test_support::shared_file("silverbox_snls80mv.csv");
  if (!fs::exists(p)) GTEST_SKIP() << "shared data not found: " << p;
  const auto rec = read_record(p);
  EXPECT_EQ(rec.size(), 131072);
  EXPECT_FALSE(rec.has_reference());
  const double T = 1.0 / 610.3515625;
  EXPECT_NEAR(rec.sample_time(), T, 1e-9 * T);
}

TEST(CsvShared, EmpsTrainHasReference) {
  const auto p = modalwatch::test_support::shared_file("emps_train.csv");
  if (!fs::exists(p)) GTEST_SKIP() << "shared data not found: " << p;
  const auto rec = read_record(p);
  EXPECT_EQ(rec.size(), 24841);
  EXPECT_TRUE(rec.has_reference());
  EXPECT_NEAR(rec.sample_time(), 0.001, 1e-9 * 0.001);
  EXPECT_EQ(read_table(p).columns, (std::vector<std::string>{"t", "u", "y", "r", "force"}));
}

}  // namespace

// The in-memory entry points (used by the fuzz harnesses) are the file readers
// without the file: same values, same messages under the given source name.
TEST_F(CsvTest, TextEntryPointsMatchTheFileReaders) {
  const std::string text = "t,u,y,r\n0,1,2,3\n0.5,nan,5,6\n1,7,8,9\n2,1,1,1\n";
  modalwatch::RecordReadOptions tolerant;
  tolerant.allow_nonfinite = true;
  tolerant.allow_gaps = true;
  const modalwatch::Record from_file = read_record(file("r.csv", text), tolerant);
  const modalwatch::Record from_text = parse_record(text, "r.csv", {}, tolerant);
  ASSERT_EQ(from_text.size(), 4);
  EXPECT_EQ(from_text.t, from_file.t);
  EXPECT_TRUE(std::isnan(from_text.u(1)));
  EXPECT_EQ(from_text.y, from_file.y);
  EXPECT_EQ(from_text.r, from_file.r);
  EXPECT_EQ(parse_table("t,u\n0,1\n", "mem").data(0, 1), 1.0);
  EXPECT_EQ(error_of([&] { parse_record(text, "mem.csv"); }),
            "mem.csv: row 3, column 'u': not a finite number (got 'nan')");
}

// RecordReader (`modalwatch track`'s reader): the same rows and the same
// errors as read_record, a block at a time, whatever the block size and
// wherever the file's 1 MiB reads split a line.
namespace {

using modalwatch::Record;
using modalwatch::RecordReader;

modalwatch::RecordReadOptions stream_options(double sample_time) {
  modalwatch::RecordReadOptions o;
  o.allow_nonfinite = true;
  o.allow_gaps = true;
  o.sample_time = sample_time;
  return o;
}

// All rows of the stream, read max_rows at a time, as a Record.
modalwatch::Record read_streamed(const std::string& path, std::size_t max_rows, double sample_time,
                                 std::vector<std::size_t>* sizes = nullptr) {
  RecordReader stream(path, stream_options(sample_time));
  std::vector<double> t, u, y, r;
  Record block;
  std::size_t n = 0;
  while ((n = stream.read(block, max_rows)) > 0) {
    EXPECT_EQ(n, static_cast<std::size_t>(block.size()));
    EXPECT_LE(n, max_rows);
    if (sizes != nullptr) sizes->push_back(n);
    t.insert(t.end(), block.t.begin(), block.t.end());
    u.insert(u.end(), block.u.begin(), block.u.end());
    y.insert(y.end(), block.y.begin(), block.y.end());
    r.insert(r.end(), block.r.begin(), block.r.end());
  }
  EXPECT_EQ(stream.read(block, max_rows), 0u);  // stays at the end
  EXPECT_EQ(stream.fraction_read(), 1.0);
  const auto vec = [](const std::vector<double>& v) {
    return Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size())));
  };
  modalwatch::Record rec;
  rec.t = vec(t);
  rec.u = vec(u);
  rec.y = vec(y);
  if (!r.empty()) rec.r = vec(r);
  return rec;
}

// `rows` rows of t = k/1000 and 17-digit u, y, r (about 70 bytes a row).
std::string long_record_text(int rows) {
  std::string text = "t,r,u,y\n";
  char line[160];
  for (int k = 0; k < rows; ++k) {
    const double x = std::sin(0.37 * k) * 1.2345678901234567;
    std::snprintf(line, sizeof line, "%.17g,%.17g,%.17g,%.17g\n", k * 1e-3, -x, x / 3.0, x * 1e-7);
    text += line;
  }
  return text;
}

}  // namespace

TEST_F(CsvTest, StreamDeliversTheRowsOfReadRecordInBlocksOfAnySize) {
  const int rows = 40001;  // 2.8 MB: three 1 MiB reads, lines split at their ends
  const std::string p = file("long.csv", long_record_text(rows));
  const modalwatch::Record whole = read_record(p, stream_options(1e-3));
  ASSERT_EQ(whole.size(), rows);
  for (const std::size_t max_rows : {std::size_t{1}, std::size_t{7}, std::size_t{4096}, std::size_t{100000}}) {
    std::vector<std::size_t> sizes;
    const modalwatch::Record streamed = read_streamed(p, max_rows, 1e-3, &sizes);
    EXPECT_EQ(streamed.t, whole.t) << max_rows;
    EXPECT_EQ(streamed.u, whole.u) << max_rows;
    EXPECT_EQ(streamed.y, whole.y) << max_rows;
    EXPECT_EQ(streamed.r, whole.r) << max_rows;
    // Full blocks, then the remainder (40001 is a multiple of none of the sizes but 1).
    ASSERT_EQ(sizes.size(), (rows + max_rows - 1) / max_rows);
    for (std::size_t i = 0; i + 1 < sizes.size(); ++i) ASSERT_EQ(sizes[i], max_rows);
    EXPECT_EQ(sizes.back(), rows - (sizes.size() - 1) * max_rows);
  }
}

TEST_F(CsvTest, StreamAcceptsWhatReadRecordAccepts) {
  // BOM, CRLF, padded fields, '+' signs, no final newline; trailing blank lines.
  const std::string text = "\xEF\xBB\xBFt , u,y\r\n0, +1.5 ,-2\r\n0.1,nan,4E1\r\n0.3,inf,2";
  const std::string p = file("a.csv", text);
  const modalwatch::Record whole = read_record(p, stream_options(0.1));
  const modalwatch::Record streamed = read_streamed(p, 2, 0.1);
  ASSERT_EQ(streamed.size(), 3);
  EXPECT_EQ(streamed.t, whole.t);
  EXPECT_EQ(streamed.y, whole.y);
  EXPECT_EQ(streamed.u(0), 1.5);
  EXPECT_TRUE(std::isnan(streamed.u(1)));
  EXPECT_TRUE(std::isinf(streamed.u(2)));
  EXPECT_FALSE(streamed.has_reference());
  EXPECT_EQ(read_streamed(file("b.csv", "t,u,y\n0,1,2\n\n \n\n"), 5, 1.0).size(), 1);
  // A line longer than the 1 MiB read (a field padded with 3 MB of blanks).
  const std::string padded = "t,u,y\n0,1,2\n1," + std::string(3 << 20, ' ') + "5,6\n2,7,8\n";
  const modalwatch::Record wide = read_streamed(file("wide.csv", padded), 10, 1.0);
  ASSERT_EQ(wide.size(), 3);
  EXPECT_EQ(wide.u(1), 5.0);
  EXPECT_EQ(wide.y(2), 8.0);
}

TEST_F(CsvTest, StreamErrorsNameFileLineAndColumnAsReadRecordDoes) {
  const auto stream_error = [&](const std::string& name, const std::string& text) {
    return error_of([&] { read_streamed(file(name, text), 3, 1.0); });
  };
  const auto file_error = [&](const std::string& name, const std::string& text) {
    return error_of([&] { read_record(file(name, text), stream_options(1.0)); });
  };
  for (const auto& [name, text] : std::vector<std::pair<std::string, std::string>>{
           {"empty.csv", ""},
           {"blank.csv", " \n\r\n\n"},
           {"bom.csv", "\xEF\xBB\xBF"},
           {"header.csv", "t,u,y\n"},
           {"nocol.csv", "t,a,y\n0,0,0\n"},
           {"dup.csv", "t,u,u\n0,1,2\n"},
           {"text.csv", "t,u,y\n0,1,2\n1,x,2\n"},
           {"short.csv", "t,u,y\n0,1,2\n1,2\n"},
           {"long.csv", "t,u,y\n0,1,2\n1,2,3,4\n"},
           {"nan_t.csv", "t,u,y\n0,1,2\nnan,2,3\n"},
           {"back.csv", "t,u,y\n0,1,2\n1,1,2\n2,1,2\n1.5,1,2\n"},
           {"step.csv", "t,u,y\n0,1,2\n1,1,2\n1.5,1,2\n"},
           {"hole.csv", "t,u,y\n0,1,2\n1,1,2\n\n2,1,2\n"},
       }) {
    const std::string streamed = stream_error(name, text);
    EXPECT_FALSE(streamed.empty()) << name;
    EXPECT_EQ(streamed, file_error(name, text)) << name;
  }
  EXPECT_CONTAINS(error_of([&] { RecordReader stream(path("missing.csv"), stream_options(1.0)); }),
                  "missing.csv: cannot open");
}

TEST_F(CsvTest, StreamNamesAMalformedRowDeepInTheRecordAfterTheRowsBeforeIt) {
  std::string text = long_record_text(40000);
  // Row k (0-based) is line k + 2: break line 30002's y.
  std::size_t at = 0;
  for (int line = 1; line < 30002; ++line) at = text.find('\n', at) + 1;
  text.replace(text.rfind(',', text.find('\n', at)) + 1, 1, "x");
  const std::string p = file("deep.csv", text);
  RecordReader stream(p, stream_options(1e-3));
  Record block;
  std::size_t rows = 0;
  std::string message;
  try {
    while (const std::size_t n = stream.read(block, 4096)) rows += n;
  } catch (const InputError& e) {
    message = e.what();
  }
  EXPECT_EQ(rows, 7u * 4096u);  // the blocks wholly before the row
  EXPECT_CONTAINS(message, "deep.csv: row 30002, column 'y': not a number");
  EXPECT_EQ(message, error_of([&] { read_record(p, stream_options(1e-3)); }));
}
