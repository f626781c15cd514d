// CSV records: parse_record (the whole text, checked for even or gapped time)
// and CsvRecordStream (a chunk of the file at a time, checked row by row). Both
// parse rows with csv_text.hpp's TableParser, so a row's error reads the same.
#include "csv_record.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../csv/csv_text.hpp"

namespace modalwatch {

using namespace csv_text;

namespace {

// Row k of the data is line k + 2 of the file (header on line 1).
int file_row(Eigen::Index k) { return static_cast<int>(k) + 2; }

// Time at file line `row` after `previous` on the line before.
void check_increasing(const std::string& path, const std::string& name, int row, double t, double previous) {
  if (!(t > previous))
    throw InputError(cell_location(path, row, name),
                     "time does not increase (got " + format_number(t) + " after " + format_number(previous) + ")");
}

void check_increasing(const std::string& path, const std::string& name, const Eigen::VectorXd& t) {
  for (Eigen::Index k = 1; k < t.size(); ++k) check_increasing(path, name, file_row(k), t(k), t(k - 1));
}

[[noreturn]] void bad_step(const std::string& path, const std::string& name, Eigen::Index k, const std::string& what) {
  throw InputError(cell_location(path, file_row(k), name), "uneven sampling: " + what);
}

// Gaps allowed: the step ending on file line `row` may be longer than the
// nominal one, never shorter by more than 1 %.
void check_gap(const std::string& path, const std::string& name, int row, double step, double nominal) {
  if (step < 0.99 * nominal)
    throw InputError(cell_location(path, row, name), "uneven sampling: step " + format_number(step) +
                                                         " is shorter than the nominal step " + format_number(nominal) +
                                                         " by more than 1 %");
}

// Every step within 1 % of the mean step.
void check_even(const std::string& path, const std::string& name, const Eigen::VectorXd& t) {
  const Eigen::Index n = t.size();
  if (n < 3) return;
  const double mean = (t(n - 1) - t(0)) / static_cast<double>(n - 1);
  for (Eigen::Index k = 1; k < n; ++k) {
    const double step = t(k) - t(k - 1);
    if (std::abs(step - mean) > 0.01 * mean)
      bad_step(
          path, name, k,
          "step " + format_number(step) + " differs from the mean step " + format_number(mean) + " by more than 1 %");
  }
}

double median_step(const Eigen::VectorXd& t) {
  std::vector<double> steps(static_cast<std::size_t>(t.size() - 1));
  for (Eigen::Index k = 1; k < t.size(); ++k) steps[static_cast<std::size_t>(k - 1)] = t(k) - t(k - 1);
  const auto mid = steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2);
  std::nth_element(steps.begin(), mid, steps.end());
  return *mid;
}

// Gaps allowed: a step may be longer than the nominal one, never shorter by more than 1 %.
void check_gaps(const std::string& path, const std::string& name, const Eigen::VectorXd& t, double nominal) {
  if (t.size() < 2) return;
  if (!(nominal > 0.0)) nominal = median_step(t);
  for (Eigen::Index k = 1; k < t.size(); ++k) check_gap(path, name, file_row(k), t(k) - t(k - 1), nominal);
}

}  // namespace

Record parse_record(std::string_view text, const std::string& path, const RecordColumns& columns,
                    const RecordReadOptions& options) {
  const Table table = parse_text(text, path, options.allow_nonfinite, columns.t);
  const int t = require_column(path, table.columns, columns.t);
  const int u = require_column(path, table.columns, columns.u);
  const int y = require_column(path, table.columns, columns.y);
  Record record;
  record.t = table.data.col(t);
  record.u = table.data.col(u);
  record.y = table.data.col(y);
  if (const int r = table.column(columns.r); r >= 0) record.r = table.data.col(r);
  for (const std::string& name : columns.further_u)
    record.further_u.emplace_back(table.data.col(require_column(path, table.columns, name)));
  check_increasing(path, columns.t, record.t);
  if (options.allow_gaps)
    check_gaps(path, columns.t, record.t, options.sample_time);
  else
    check_even(path, columns.t, record.t);
  return record;
}

// The file is read in large chunks into one buffer; a line split by a chunk's
// end is moved to the front before the next read. Rows are parsed in place by
// the same TableParser as read_table, and checked as parse_record checks them.
struct CsvRecordStream::Impl {
  static constexpr std::size_t kChunk = 1 << 20;

  std::string path;
  std::string t_name;
  RecordReadOptions options;
  int fd = -1;
  std::uint64_t size = 0;      // of the file, 0 when unknown
  std::uint64_t consumed = 0;  // bytes before buffer[begin]
  std::string buffer;
  std::size_t begin = 0, end = 0;
  bool eof = false;
  int line = 0;  // 1-based number of the last line taken
  std::vector<std::string> columns;
  std::unique_ptr<TableParser> parser;
  int ct = -1, cu = -1, cy = -1, cr = -1;
  std::vector<int> cfu;  // the further inputs' columns
  std::vector<double> values;
  std::uint64_t rows = 0;
  double previous_t = 0.0;
  bool finished = false;

  ~Impl() {
    if (fd >= 0) ::close(fd);
  }

  // Moves the partial line to the front (growing the buffer for a line longer
  // than it) and reads more behind it.
  void refill() {
    if (begin > 0) {
      std::memmove(buffer.data(), buffer.data() + begin, end - begin);
      end -= begin;
      begin = 0;
    }
    if (buffer.size() - end < kChunk / 2) buffer.resize(std::max(2 * buffer.size(), end + kChunk));
    for (;;) {
      const ssize_t got = ::read(fd, buffer.data() + end, buffer.size() - end);
      if (got < 0 && errno == EINTR) continue;
      if (got < 0) throw InputError(path, std::string("cannot read: ") + std::strerror(errno));
      if (got == 0) eof = true;
      end += static_cast<std::size_t>(got);
      return;
    }
  }

  // The next line without its '\n' (a final line without one counts); false at the end.
  bool next_line(std::string_view& out) {
    for (;;) {
      const char* first = buffer.data() + begin;
      if (const void* nl = std::memchr(first, '\n', end - begin)) {
        const std::size_t length = static_cast<std::size_t>(static_cast<const char*>(nl) - first);
        out = std::string_view(first, length);
        begin += length + 1;
        consumed += length + 1;
        ++line;
        return true;
      }
      if (eof) {
        if (begin == end) return false;
        out = std::string_view(first, end - begin);
        consumed += end - begin;
        begin = end;
        ++line;
        return true;
      }
      refill();
    }
  }

  void open() {
    fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw InputError(path, std::string("cannot open: ") + std::strerror(errno));
    struct stat st {};
    if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode)) size = static_cast<std::uint64_t>(st.st_size);
    buffer.resize(kChunk);
    while (!eof && end < 3) refill();
    if (std::string_view(buffer.data(), end).substr(0, kBom.size()) == kBom) begin = consumed = kBom.size();
  }

  // Whether the rest of the file is blank too (after a blank first line).
  bool rest_is_blank() {
    std::string_view rest;
    while (next_line(rest))
      if (rest.find_first_not_of(kBlankOrBom) != std::string_view::npos) return false;
    return true;
  }

  void read_header(const RecordColumns& names) {
    std::string_view first;
    if (!next_line(first)) throw InputError(path, "empty file (expected a header line of column names)");
    const std::string header(first);  // rest_is_blank reads on, over the buffer
    if (header.find_first_not_of(kBlankOrBom) == std::string::npos && rest_is_blank())
      throw InputError(path, "empty file (expected a header line of column names)");
    columns = parse_header(path, header);
    ct = require_column(path, columns, names.t);
    cu = require_column(path, columns, names.u);
    cy = require_column(path, columns, names.y);
    for (const std::string& name : names.further_u) cfu.push_back(require_column(path, columns, name));
    if (const auto it = std::find(columns.begin(), columns.end(), names.r); it != columns.end())
      cr = static_cast<int>(it - columns.begin());
    std::vector<bool> nonfinite_ok(columns.size(), options.allow_nonfinite);
    nonfinite_ok[static_cast<std::size_t>(ct)] = false;
    parser = std::make_unique<TableParser>(path, columns, std::move(nonfinite_ok));
    values.resize(columns.size());
  }

  // The line-reader interface check_trailing_blank takes.
  bool next(std::string_view& out) { return next_line(out); }
  int number() const { return line; }
};

CsvRecordStream::CsvRecordStream(const std::string& path, const RecordColumns& columns,
                                 const RecordReadOptions& options)
    : impl_(std::make_unique<Impl>()) {
  impl_->path = path;
  impl_->t_name = columns.t;
  impl_->options = options;
  impl_->open();
  impl_->read_header(columns);
}

CsvRecordStream::CsvRecordStream(CsvRecordStream&&) noexcept = default;
CsvRecordStream& CsvRecordStream::operator=(CsvRecordStream&&) noexcept = default;
CsvRecordStream::~CsvRecordStream() = default;

bool CsvRecordStream::has_reference() const { return impl_->cr >= 0; }
std::uint64_t CsvRecordStream::bytes_read() const { return impl_->consumed; }
std::uint64_t CsvRecordStream::file_size() const { return impl_->size; }

std::size_t CsvRecordStream::read(Record& block, std::size_t max_rows) {
  Impl& s = *impl_;
  const auto capacity = static_cast<Eigen::Index>(max_rows);
  block.t.resize(capacity);  // no allocation when the size is the last block's
  block.u.resize(capacity);
  block.y.resize(capacity);
  block.r.resize(s.cr >= 0 ? capacity : 0);
  block.further_u.resize(s.cfu.size());
  for (Eigen::VectorXd& v : block.further_u) v.resize(capacity);
  Eigen::Index n = 0;
  std::string_view line;
  while (n < capacity && !s.finished) {
    if (!s.next_line(line)) {
      s.finished = true;
      break;
    }
    if (is_blank(line)) {
      check_trailing_blank(s.path, s);
      s.finished = true;
      break;
    }
    s.parser->parse_row(line, s.line, s.values.data());
    const double t = s.values[static_cast<std::size_t>(s.ct)];
    if (s.rows > 0) {
      check_increasing(s.path, s.t_name, s.line, t, s.previous_t);
      check_gap(s.path, s.t_name, s.line, t - s.previous_t, s.options.sample_time);
    }
    s.previous_t = t;
    ++s.rows;
    block.t(n) = t;
    block.u(n) = s.values[static_cast<std::size_t>(s.cu)];
    block.y(n) = s.values[static_cast<std::size_t>(s.cy)];
    if (s.cr >= 0) block.r(n) = s.values[static_cast<std::size_t>(s.cr)];
    for (std::size_t j = 0; j < s.cfu.size(); ++j) block.further_u[j](n) = s.values[static_cast<std::size_t>(s.cfu[j])];
    ++n;
  }
  if (s.finished && s.rows == 0) throw InputError(s.path, "no data rows after the header");
  if (n < capacity) {
    block.t.conservativeResize(n);
    block.u.conservativeResize(n);
    block.y.conservativeResize(n);
    if (s.cr >= 0) block.r.conservativeResize(n);
    for (Eigen::VectorXd& v : block.further_u) v.conservativeResize(n);
  }
  return static_cast<std::size_t>(n);
}

}  // namespace modalwatch
