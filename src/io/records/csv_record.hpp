#pragma once
// CSV records for records.cpp: the streamed reader behind RecordReader.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "modalwatch/io/records.hpp"

namespace modalwatch {

// A CSV record read a chunk of the file at a time. The header and columns are
// checked when it is opened; a row's errors (parse_record's, with
// options.allow_gaps and the nominal options.sample_time) when read() reaches it.
class CsvRecordStream {
 public:
  CsvRecordStream(const std::string& path, const RecordColumns& columns, const RecordReadOptions& options);
  CsvRecordStream(CsvRecordStream&&) noexcept;
  CsvRecordStream& operator=(CsvRecordStream&&) noexcept;
  ~CsvRecordStream();

  bool has_reference() const;
  std::size_t read(Record& block, std::size_t max_rows);
  std::uint64_t bytes_read() const;  // of the file, up to the last row read
  std::uint64_t file_size() const;   // 0 when unknown (a pipe)

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace modalwatch
