// CSV records. The whole file is read into memory (or, by RecordStream, a
// large chunk at a time) and parsed in place with std::from_chars: iostream per
// field is an order of magnitude too slow for records of millions of rows.
#include "modalwatch/io/csv.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string_view>
#include <system_error>

#include "modalwatch/error.hpp"
#include "modalwatch/io/atomic_file.hpp"

namespace modalwatch {
namespace {

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

std::string read_file(const std::string& path) {
  File f(std::fopen(path.c_str(), "rb"));
  if (!f) throw InputError(path, std::string("cannot open: ") + std::strerror(errno));
  // One allocation of the file's size, then one read (growing a string chunk
  // by chunk costs as much as parsing).
  std::string text;
  if (std::fseek(f.get(), 0, SEEK_END) == 0) {
    const long size = std::ftell(f.get());
    if (size > 0) text.resize(static_cast<std::size_t>(size));
    std::rewind(f.get());
  }
  std::size_t used = std::fread(text.data(), 1, text.size(), f.get());
  text.resize(used);
  char buffer[1 << 16];  // the file may have grown, or not be seekable
  for (std::size_t got = 0; (got = std::fread(buffer, 1, sizeof buffer, f.get())) > 0;) text.append(buffer, got);
  if (std::ferror(f.get())) throw InputError(path, std::string("cannot read: ") + std::strerror(errno));
  return text;
}

std::string_view trim(std::string_view s) {
  const auto blank = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
  while (!s.empty() && blank(s.front())) s.remove_prefix(1);
  while (!s.empty() && blank(s.back())) s.remove_suffix(1);
  return s;
}

bool is_blank(std::string_view line) { return trim(line).empty(); }

// Splits text into lines without copying; a final line without '\n' counts.
class LineReader {
 public:
  explicit LineReader(std::string_view text) : rest_(text) {}
  bool next(std::string_view& line) {
    if (rest_.empty()) return false;
    const std::size_t end = rest_.find('\n');
    line = rest_.substr(0, end);
    rest_.remove_prefix(end == std::string_view::npos ? rest_.size() : end + 1);
    ++number_;
    return true;
  }
  int number() const { return number_; }  // 1-based line number of the last line
  std::string_view rest() const { return rest_; }

 private:
  std::string_view rest_;
  int number_ = 0;
};

std::string row_location(const std::string& path, int row) {
  return path + ": row " + std::to_string(row);
}
std::string cell_location(const std::string& path, int row, const std::string& column) {
  return row_location(path, row) + ", column '" + column + "'";
}

std::string format_number(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.17g", v);
  return buffer;
}

std::string join(const std::vector<std::string>& names) {
  std::string out;
  for (const auto& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

std::vector<std::string> parse_header(const std::string& path, std::string_view line) {
  std::vector<std::string> columns;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    const std::string_view field = trim(line.substr(start, comma - start));
    if (field.empty())
      throw InputError(row_location(path, 1),
                       "empty column name in header (column " + std::to_string(columns.size() + 1) + ")");
    std::string name(field);
    if (std::find(columns.begin(), columns.end(), name) != columns.end())
      throw InputError(cell_location(path, 1, name), "duplicate column name");
    columns.push_back(std::move(name));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return columns;
}

// Parses one field completely; from_chars rejects '+', so it is skipped here.
bool parse_number(std::string_view field, double& value) {
  if (field.size() > 1 && field.front() == '+' && field[1] != '-') field.remove_prefix(1);
  const char* end = field.data() + field.size();
  const auto [ptr, ec] = std::from_chars(field.data(), end, value);
  return ec == std::errc() && ptr == end;
}

std::size_t count_newlines(std::string_view text) {
  return static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n'));
}

class TableParser {
 public:
  // nonfinite_ok[c]: column c may hold nan/inf (records passed on to the
  // estimator, which counts them).
  TableParser(const std::string& path, const std::vector<std::string>& columns, std::vector<bool> nonfinite_ok)
      : path_(path), columns_(columns), nonfinite_ok_(std::move(nonfinite_ok)) {}

  // Fills values[0, columns) from the line with 1-based number `row`.
  void parse_row(std::string_view line, int row, double* values) {
    const std::size_t n = columns_.size();
    std::size_t start = 0;
    for (std::size_t c = 0; c < n; ++c) {
      const std::size_t comma = line.find(',', start);
      if (comma == std::string_view::npos && c + 1 < n) short_row(row, c + 1);
      const std::size_t end = c + 1 < n ? comma : line.size();
      if (c + 1 == n && comma != std::string_view::npos) long_row(line, row);
      values[c] = field(line.substr(start, end - start), row, c);
      start = end + 1;
    }
  }

 private:
  double field(std::string_view text, int row, std::size_t c) const {
    const std::string_view s = trim(text);
    double value = 0.0;
    if (!parse_number(s, value))
      throw InputError(cell_location(path_, row, columns_[c]),
                       s.empty() ? "empty field" : "not a number (got '" + std::string(s) + "')");
    if (!std::isfinite(value) && !nonfinite_ok_[c])
      throw InputError(cell_location(path_, row, columns_[c]),
                       "not a finite number (got '" + std::string(s) + "')");
    return value;
  }
  [[noreturn]] void short_row(int row, std::size_t fields) const {
    throw InputError(cell_location(path_, row, columns_[fields]),
                     "row has " + std::to_string(fields) + " fields, header has " +
                         std::to_string(columns_.size()));
  }
  [[noreturn]] void long_row(std::string_view line, int row) const {
    const std::size_t fields = static_cast<std::size_t>(std::count(line.begin(), line.end(), ',')) + 1;
    throw InputError(row_location(path_, row), "row has " + std::to_string(fields) +
                                                   " fields, header has " +
                                                   std::to_string(columns_.size()));
  }

  const std::string& path_;
  const std::vector<std::string>& columns_;
  std::vector<bool> nonfinite_ok_;
};

// Blank lines are accepted only at the end, so that data row k is file line k + 2.
// `lines`: a LineReader, or RecordStream's reader (next(line), number()).
template <class Lines>
void check_trailing_blank(const std::string& path, Lines& lines) {
  std::string_view line;
  const int first_blank = lines.number();
  while (lines.next(line))
    if (!is_blank(line))
      throw InputError(row_location(path, first_blank), "empty row before more data");
}

constexpr std::string_view kBom = "\xEF\xBB\xBF";  // UTF-8 byte order mark
// A file of nothing but these is "empty".
constexpr std::string_view kBlankOrBom = " \t\r\n\xEF\xBB\xBF";

std::string_view strip_bom(std::string_view text) {
  if (text.substr(0, kBom.size()) == kBom) text.remove_prefix(kBom.size());
  return text;
}

}  // namespace

int Table::column(const std::string& name) const {
  const auto it = std::find(columns.begin(), columns.end(), name);
  return it == columns.end() ? -1 : static_cast<int>(it - columns.begin());
}

namespace {

// parse_table, with nan/inf accepted in every column except `finite_column`
// when allow_nonfinite is set. `path` names the source in messages.
Table parse_text(std::string_view text, const std::string& path, bool allow_nonfinite,
                 const std::string& finite_column) {
  LineReader lines(strip_bom(text));
  std::string_view line;
  if (text.find_first_not_of(kBlankOrBom) == std::string_view::npos || !lines.next(line))
    throw InputError(path, "empty file (expected a header line of column names)");
  Table table;
  table.columns = parse_header(path, line);
  table.data.resize(static_cast<Eigen::Index>(count_newlines(lines.rest()) + 1),
                    static_cast<Eigen::Index>(table.columns.size()));
  std::vector<bool> nonfinite_ok(table.columns.size(), allow_nonfinite);
  if (const int c = table.column(finite_column); c >= 0) nonfinite_ok[static_cast<std::size_t>(c)] = false;
  TableParser parser(path, table.columns, std::move(nonfinite_ok));
  std::vector<double> values(table.columns.size());
  Eigen::Index rows = 0;
  while (lines.next(line)) {
    if (is_blank(line)) {
      check_trailing_blank(path, lines);
      break;
    }
    parser.parse_row(line, lines.number(), values.data());
    for (std::size_t c = 0; c < values.size(); ++c) table.data(rows, static_cast<Eigen::Index>(c)) = values[c];
    ++rows;
  }
  if (rows == 0) throw InputError(path, "no data rows after the header");
  table.data.conservativeResize(rows, Eigen::NoChange);
  return table;
}

}  // namespace

Table parse_table(std::string_view text, const std::string& source) {
  return parse_text(text, source, false, "");
}

Table read_table(const std::string& path) { return parse_table(read_file(path), path); }

namespace {

int require_column(const std::string& path, const std::vector<std::string>& columns, const std::string& name) {
  const auto it = std::find(columns.begin(), columns.end(), name);
  if (it == columns.end())
    throw InputError(path, "missing column '" + name + "' (available: " + join(columns) + ")");
  return static_cast<int>(it - columns.begin());
}
int require_column(const std::string& path, const Table& table, const std::string& name) {
  return require_column(path, table.columns, name);
}

// Row k of the data is line k + 2 of the file (header on line 1).
int file_row(Eigen::Index k) { return static_cast<int>(k) + 2; }

// Time at file line `row` after `previous` on the line before.
void check_increasing(const std::string& path, const std::string& name, int row, double t, double previous) {
  if (!(t > previous))
    throw InputError(cell_location(path, row, name), "time does not increase (got " + format_number(t) + " after " +
                                                         format_number(previous) + ")");
}

void check_increasing(const std::string& path, const std::string& name, const Eigen::VectorXd& t) {
  for (Eigen::Index k = 1; k < t.size(); ++k) check_increasing(path, name, file_row(k), t(k), t(k - 1));
}

[[noreturn]] void bad_step(const std::string& path, const std::string& name, Eigen::Index k,
                           const std::string& what) {
  throw InputError(cell_location(path, file_row(k), name), "uneven sampling: " + what);
}

// Gaps allowed: the step ending on file line `row` may be longer than the
// nominal one, never shorter by more than 1 %.
void check_gap(const std::string& path, const std::string& name, int row, double step, double nominal) {
  if (step < 0.99 * nominal)
    throw InputError(cell_location(path, row, name), "uneven sampling: step " + format_number(step) +
                                                         " is shorter than the nominal step " +
                                                         format_number(nominal) + " by more than 1 %");
}

// Every step within 1 % of the mean step.
void check_even(const std::string& path, const std::string& name, const Eigen::VectorXd& t) {
  const Eigen::Index n = t.size();
  if (n < 3) return;
  const double mean = (t(n - 1) - t(0)) / static_cast<double>(n - 1);
  for (Eigen::Index k = 1; k < n; ++k) {
    const double step = t(k) - t(k - 1);
    if (std::abs(step - mean) > 0.01 * mean)
      bad_step(path, name, k,
               "step " + format_number(step) + " differs from the mean step " + format_number(mean) +
                   " by more than 1 %");
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

Record read_record(const std::string& path, const RecordColumns& columns, const RecordReadOptions& options) {
  return parse_record(read_file(path), path, columns, options);
}

Record parse_record(std::string_view text, const std::string& path, const RecordColumns& columns,
                    const RecordReadOptions& options) {
  const Table table = parse_text(text, path, options.allow_nonfinite, columns.t);
  const int t = require_column(path, table, columns.t);
  const int u = require_column(path, table, columns.u);
  const int y = require_column(path, table, columns.y);
  Record record;
  record.t = table.data.col(t);
  record.u = table.data.col(u);
  record.y = table.data.col(y);
  if (const int r = table.column(columns.r); r >= 0) record.r = table.data.col(r);
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
struct RecordStream::Impl {
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

RecordStream::RecordStream(const std::string& path, const RecordColumns& columns, const RecordReadOptions& options)
    : impl_(std::make_unique<Impl>()) {
  if (!options.allow_gaps || !(options.sample_time > 0.0))
    throw std::invalid_argument("RecordStream needs allow_gaps and a nominal sample_time");
  impl_->path = path;
  impl_->t_name = columns.t;
  impl_->options = options;
  impl_->open();
  impl_->read_header(columns);
}

RecordStream::RecordStream(RecordStream&&) noexcept = default;
RecordStream& RecordStream::operator=(RecordStream&&) noexcept = default;
RecordStream::~RecordStream() = default;

bool RecordStream::has_reference() const { return impl_->cr >= 0; }
std::uint64_t RecordStream::bytes_read() const { return impl_->consumed; }
std::uint64_t RecordStream::file_size() const { return impl_->size; }

std::size_t RecordStream::read(RecordBlock& block, std::size_t max_rows) {
  Impl& s = *impl_;
  block.t.clear();
  block.u.clear();
  block.y.clear();
  block.r.clear();
  std::string_view line;
  while (block.size() < max_rows && !s.finished) {
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
    block.t.push_back(t);
    block.u.push_back(s.values[static_cast<std::size_t>(s.cu)]);
    block.y.push_back(s.values[static_cast<std::size_t>(s.cy)]);
    if (s.cr >= 0) block.r.push_back(s.values[static_cast<std::size_t>(s.cr)]);
  }
  if (s.finished && s.rows == 0) throw InputError(s.path, "no data rows after the header");
  return block.size();
}

namespace {

// std::to_chars with precision 17 prints what %.17g prints, several times faster
// than fprintf; rows are buffered and written in large blocks.
void write_rows(AtomicFile& f, const std::vector<std::string>& columns, const Eigen::MatrixXd& data) {
  std::string out;
  for (std::size_t j = 0; j < columns.size(); ++j) (out += j == 0 ? "" : ",") += columns[j];
  out += '\n';
  char field[64];
  for (Eigen::Index i = 0; i < data.rows(); ++i) {
    for (Eigen::Index j = 0; j < data.cols(); ++j) {
      if (j > 0) out += ',';
      const auto end = std::to_chars(field, field + sizeof field, data(i, j), std::chars_format::general, 17).ptr;
      out.append(field, end);
    }
    out += '\n';
    if (out.size() > (1 << 16)) {
      f.write(out);
      out.clear();
    }
  }
  f.write(out);
}

// The header has no quoting, so names that would split or shift columns are refused.
void check_columns(const std::string& path, const std::vector<std::string>& columns,
                   const Eigen::MatrixXd& data) {
  if (static_cast<Eigen::Index>(columns.size()) != data.cols())
    throw InputError(path, "cannot write: " + std::to_string(columns.size()) + " column names for " +
                               std::to_string(data.cols()) + " columns");
  for (const auto& name : columns)
    if (name.empty() || name.find_first_of(",\n\r") != std::string::npos || trim(name) != name)
      throw InputError(path, "cannot write: invalid column name '" + name + "'");
}

}  // namespace

void write_table(const std::string& path, const std::vector<std::string>& columns,
                 const Eigen::MatrixXd& data) {
  check_columns(path, columns, data);
  try {
    AtomicFile file(path);
    write_rows(file, columns, data);
    file.commit();
  } catch (const std::system_error& e) {
    throw InputError(path, std::string("cannot write: ") + e.code().message());
  }
}

void write_record(const std::string& path, const Record& record) {
  const bool with_r = record.has_reference();
  const Eigen::Index n = record.size();
  if (record.u.size() != n || record.y.size() != n)
    throw InputError(path, "cannot write: t, u and y differ in length");
  std::vector<std::string> columns{"t"};
  Eigen::MatrixXd data(n, with_r ? 4 : 3);
  data.col(0) = record.t;
  if (with_r) {
    columns.push_back("r");
    data.col(1) = record.r;
  }
  columns.insert(columns.end(), {"u", "y"});
  data.col(with_r ? 2 : 1) = record.u;
  data.col(with_r ? 3 : 2) = record.y;
  write_table(path, columns, data);
}

}  // namespace modalwatch
