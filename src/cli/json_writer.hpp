#pragma once
// JSON for the reports the commands write: strings escaped (quotes,
// backslashes, control characters; a byte that is not part of valid UTF-8
// becomes U+FFFD, so a path of arbitrary bytes still gives valid JSON), numbers
// finite or null, and the commas and nesting kept by the writer.
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace modalwatch::cli {

namespace json_detail {

// Length of the valid UTF-8 sequence at s[i], or 0 (RFC 3629: no overlong
// forms, no surrogates, nothing above U+10FFFF).
inline std::size_t utf8_length(std::string_view s, std::size_t i) {
  const auto byte = [&](std::size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char c = byte(i);
  std::size_t n = 0;
  unsigned char lo = 0x80, hi = 0xBF;  // range of the second byte
  if (c >= 0xC2 && c <= 0xDF) {
    n = 2;
  } else if (c >= 0xE0 && c <= 0xEF) {
    n = 3;
    if (c == 0xE0) lo = 0xA0;
    if (c == 0xED) hi = 0x9F;
  } else if (c >= 0xF0 && c <= 0xF4) {
    n = 4;
    if (c == 0xF0) lo = 0x90;
    if (c == 0xF4) hi = 0x8F;
  } else {
    return 0;
  }
  if (i + n > s.size() || byte(i + 1) < lo || byte(i + 1) > hi) return 0;
  for (std::size_t k = 2; k < n; ++k)
    if (byte(i + k) < 0x80 || byte(i + k) > 0xBF) return 0;
  return n;
}

}  // namespace json_detail

// s as a JSON string literal, quotes included.
inline std::string json_string(std::string_view s) {
  std::string out = "\"";
  for (std::size_t i = 0; i < s.size();) {
    const auto c = static_cast<unsigned char>(s[i]);
    if (c >= 0x80) {
      const std::size_t n = json_detail::utf8_length(s, i);
      if (n == 0) {
        out += "\\ufffd";
        ++i;
      } else {
        out.append(s, i, n);
        i += n;
      }
      continue;
    }
    // The characters with a two-character escape, and their letters.
    constexpr std::string_view kEscaped = "\"\\\b\f\n\r\t", kLetters = "\"\\bfnrt";
    if (const auto e = kEscaped.find(static_cast<char>(c)); e != std::string_view::npos) {
      out += '\\';
      out += kLetters[e];
    } else if (c < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
    ++i;
  }
  return out + "\"";
}

// v to `precision` significant digits ("%.*g"), or null when not finite.
inline std::string json_number(double v, int precision) {
  if (!std::isfinite(v)) return "null";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*g", precision, v);
  return buf;
}

// Writes one document in order: key() then a value inside an object, values
// inside an array. Misuse (a value without its key, closing what is not open)
// throws std::logic_error.
class JsonWriter {
 public:
  // Layout::lines puts each element of an array on a line of its own.
  enum class Layout { inline_, lines };

  JsonWriter& begin_object() {
    open_value();
    out_ += '{';
    stack_.push_back({true, false});
    return *this;
  }
  JsonWriter& end_object() { return close(true, '}'); }
  JsonWriter& begin_array(Layout layout = Layout::inline_) {
    open_value();
    out_ += '[';
    stack_.push_back({false, layout == Layout::lines});
    return *this;
  }
  JsonWriter& end_array() { return close(false, ']'); }

  JsonWriter& key(std::string_view k) {
    if (stack_.empty() || !stack_.back().object || stack_.back().after_key)
      throw std::logic_error("JsonWriter: a key outside an object");
    separate();
    out_ += json_string(k) + ": ";
    stack_.back().after_key = true;
    return *this;
  }
  JsonWriter& value(std::string_view s) { return raw(json_string(s)); }
  JsonWriter& value(const char* s) { return value(std::string_view(s)); }
  JsonWriter& value(const std::string& s) { return value(std::string_view(s)); }
  JsonWriter& value(double v, int precision = 17) { return raw(json_number(v, precision)); }
  JsonWriter& value(int v) { return raw(std::to_string(v)); }
  JsonWriter& value(bool b) { return raw(b ? "true" : "false"); }
  JsonWriter& null() { return raw("null"); }

  // The document with a final newline.
  std::string finish() {
    if (!stack_.empty() || out_.empty()) throw std::logic_error("JsonWriter: the document is not complete");
    return out_ + "\n";
  }

 private:
  struct Level {
    bool object = false;
    bool lines = false;
    bool empty = true;
    bool after_key = false;
  };

  // Commas (and line breaks) between the elements of a container.
  void separate() {
    Level& l = stack_.back();
    if (!l.empty)
      out_ += l.lines ? ",\n  " : ", ";
    else if (l.lines)
      out_ += "\n  ";
    l.empty = false;
  }
  void open_value() {
    if (stack_.empty()) {
      if (!out_.empty()) throw std::logic_error("JsonWriter: a second document");
      return;
    }
    Level& l = stack_.back();
    if (l.object) {
      if (!l.after_key) throw std::logic_error("JsonWriter: a value without its key");
      l.after_key = false;
    } else {
      separate();
    }
  }
  JsonWriter& raw(const std::string& text) {
    open_value();
    out_ += text;
    return *this;
  }
  JsonWriter& close(bool object, char bracket) {
    if (stack_.empty() || stack_.back().object != object || stack_.back().after_key)
      throw std::logic_error("JsonWriter: closing what is not open");
    if (stack_.back().lines && !stack_.back().empty) out_ += '\n';
    stack_.pop_back();
    out_ += bracket;
    return *this;
  }

  std::vector<Level> stack_;
  std::string out_;
};

}  // namespace modalwatch::cli
