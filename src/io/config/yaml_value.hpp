#pragma once
// The YAML validation layer of the configuration: every key is read through
// Value/Map, which know the file, the line and the dotted key path, so that any
// rejection names all three: a config error must be fixable from the message
// alone.
#include <yaml-cpp/yaml.h>

#include <charconv>
#include <cstdio>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "modalwatch/error.hpp"

namespace modalwatch::config_detail {

inline constexpr double kTwoPi = 6.283185307179586476925286766559;

using Keys = std::vector<std::string_view>;

inline std::string join(const Keys& keys) {
  std::string out;
  for (const auto k : keys) (out += out.empty() ? "" : ", ") += k;
  return out;
}

inline std::string format_number(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.17g", v);
  return buffer;
}

// A node as the user wrote it, for "(got ...)": quoted strings keep their quotes.
inline std::string render(const YAML::Node& node) {
  if (!node.IsDefined() || node.IsNull()) return "null";
  if (node.IsScalar()) return node.Tag() == "!" ? "\"" + node.Scalar() + "\"" : node.Scalar();
  YAML::Emitter out;
  out.SetSeqFormat(YAML::Flow);
  out.SetMapFormat(YAML::Flow);
  out << node;
  std::string text = out.c_str();
  return text.size() > 60 ? text.substr(0, 57) + "..." : text;
}

// Plain (unquoted) scalars only: `wn: "2"` is a string, not a number. The whole
// scalar must be consumed, so `2 rad/s` is rejected rather than read as 2.
template <typename T>
inline bool parse_plain(const YAML::Node& node, T& value) {
  if (!node.IsScalar() || node.Tag() == "!") return false;
  std::string_view s = node.Scalar();
  if (s.size() > 1 && s.front() == '+' && s[1] != '-') s.remove_prefix(1);  // from_chars rejects '+'
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
  return !s.empty() && ec == std::errc() && ptr == s.data() + s.size();
}

// One node of the document with its place: the file, the 1-based line and
// the dotted key path (`model.submodels[2].zeta`).
class Value {
 public:
  Value(const std::string& source, YAML::Node node, std::string path, int line)
      : source_(&source), node_(std::move(node)), path_(std::move(path)), line_(line) {}

  const YAML::Node& node() const { return node_; }
  const std::string& path() const { return path_; }
  const std::string& source() const { return *source_; }
  int line() const { return line_; }

  std::string location() const {
    std::string loc = *source_ + ":" + std::to_string(line_);
    return path_.empty() ? loc : loc + ": key '" + path_ + "'";
  }
  [[noreturn]] void fail(const std::string& what) const {
    throw InputError(location(), what + " (got " + render(node_) + ")");
  }
  [[noreturn]] void fail_plain(const std::string& what) const { throw InputError(location(), what); }

  Value child(const std::string& key, YAML::Node node, int line) const {
    return Value(*source_, std::move(node), path_.empty() ? key : path_ + "." + key, line);
  }

  double number() const {
    double v = 0.0;
    if (!parse_plain(node_, v)) fail("expected a number");
    if (!std::isfinite(v)) fail("must be a finite number");
    return v;
  }
  double positive() const {
    const double v = number();
    if (!(v > 0.0)) fail("must be > 0");
    return v;
  }
  double nonzero() const {
    const double v = number();
    if (v == 0.0) fail("must be != 0");
    return v;
  }
  double at_least(double lo) const {
    const double v = number();
    if (!(v >= lo)) fail("must be >= " + format_number(lo));
    return v;
  }
  double above(double lo) const {
    const double v = number();
    if (!(v > lo)) fail("must be > " + format_number(lo));
    return v;
  }
  // Plain `true` or `false` only: YAML 1.1's yes/no/on/off are too easy to mistype.
  bool boolean() const {
    if (node_.IsScalar() && node_.Tag() != "!") {
      if (node_.Scalar() == "true") return true;
      if (node_.Scalar() == "false") return false;
    }
    fail("expected true or false");
  }
  long long integer(long long lo, long long hi) const {
    long long v = 0;
    if (!parse_plain(node_, v)) fail("expected an integer");
    if (v < lo || v > hi) {
      const bool open_ended = hi >= std::numeric_limits<int>::max();  // no useful upper bound to show
      fail(open_ended ? "must be >= " + std::to_string(lo)
                      : "must be in " + std::to_string(lo) + ".." + std::to_string(hi));
    }
    return v;
  }
  std::string text() const {
    if (!node_.IsScalar() || node_.Scalar().empty()) fail("expected a non-empty string");
    return node_.Scalar();
  }
  std::string choice(const Keys& options) const {
    const std::string s = text();
    if (std::find(options.begin(), options.end(), s) == options.end()) fail("must be one of " + join(options));
    return s;
  }

  std::vector<Value> items() const {
    if (!node_.IsSequence()) fail("expected a list");
    std::vector<Value> out;
    for (std::size_t i = 0; i < node_.size(); ++i) {
      const YAML::Node item = node_[i];
      const int line = item.Mark().line >= 0 ? item.Mark().line + 1 : line_;
      out.emplace_back(*source_, item, path_ + "[" + std::to_string(i) + "]", line);
    }
    return out;
  }
  std::vector<double> numbers() const {
    std::vector<double> out;
    for (const auto& item : items()) out.push_back(item.number());
    return out;
  }
  std::vector<double> nonempty_numbers() const {
    std::vector<double> out = numbers();
    if (out.empty()) fail("must not be empty");
    return out;
  }

 private:
  const std::string* source_;
  YAML::Node node_;
  std::string path_;
  int line_;
};

// A YAML map whose keys are checked: duplicates and unknown keys are errors.
class Map {
 public:
  explicit Map(Value self) : self_(std::move(self)) {
    if (!self_.node().IsMap()) self_.fail("expected a map of keys");
    for (auto it = self_.node().begin(); it != self_.node().end(); ++it) add(it->first, it->second);
  }

  const Value& self() const { return self_; }

  // Rejects any key not in `allowed`; `what` says whose keys these are.
  void allow(const Keys& allowed, const std::string& what) const {
    for (const auto& [key, value] : entries_)
      if (std::find(allowed.begin(), allowed.end(), key) == allowed.end())
        value.fail_plain("unknown key" + (what.empty() ? "" : " for " + what) + " (allowed: " + join(allowed) + ")");
  }

  bool has(std::string_view key) const { return find(key) != nullptr; }
  std::optional<Value> get(std::string_view key) const {
    const Value* v = find(key);
    return v ? std::optional<Value>(*v) : std::nullopt;
  }
  // A missing key is reported at the line of this map.
  Value require(std::string_view key, const std::string& why = "") const {
    if (const Value* v = find(key)) return *v;
    missing(key, why);
  }
  [[noreturn]] void missing(std::string_view key, const std::string& why) const {
    const Value place = self_.child(std::string(key), YAML::Node(), self_.line());
    place.fail_plain("missing required key" + (why.empty() ? "" : " (" + why + ")"));
  }

 private:
  void add(const YAML::Node& key, const YAML::Node& value) {
    const int key_line = key.Mark().line + 1;
    if (!key.IsScalar()) self_.child("?", key, key_line).fail("keys must be plain names");
    const std::string name = key.Scalar();
    const Value entry = self_.child(name, value, key_line);
    if (const Value* first = find(name))
      entry.fail_plain("duplicate key (first at line " + std::to_string(first->line()) + ")");
    entries_.emplace_back(name, entry);
  }
  const Value* find(std::string_view key) const {
    for (const auto& [k, v] : entries_)
      if (k == key) return &v;
    return nullptr;
  }

  Value self_;
  std::vector<std::pair<std::string, Value>> entries_;
};

inline double optional_number(const Map& m, std::string_view key, double fallback) {
  const auto v = m.get(key);
  return v ? v->number() : fallback;
}

// `a` or `b` but not both; `scale` converts b's unit to a's.
inline std::optional<double> one_of(const Map& m, std::string_view a, std::string_view b, double scale, bool positive) {
  const auto va = m.get(a);
  const auto vb = m.get(b);
  if (va && vb) vb->fail_plain("give " + std::string(a) + " or " + std::string(b) + ", not both");
  if (va) return positive ? va->positive() : va->number();
  if (vb) return (positive ? vb->positive() : vb->number()) * scale;
  return std::nullopt;
}

}  // namespace modalwatch::config_detail
