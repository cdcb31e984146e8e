// Whitespace-separated tokens of a text file, for the ASCII readers (meshes, vessel trees).
// Internal to the core library.
#pragma once

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <istream>
#include <string>
#include <vector>

namespace liver_sim {

// Tokens with their line numbers, for messages that point into the file; errors throw `Error`.
template <typename Error>
class TextTokens {
 public:
  TextTokens(const std::string& path, std::istream& in) : path_(path) {
    std::string line;
    while (std::getline(in, line)) lines_.push_back(line);
  }

  bool at_end() {
    skip_space();
    return line_ >= lines_.size();
  }

  std::string next(const char* expected) {
    skip_space();
    if (line_ >= lines_.size()) fail(std::string("unexpected end of file, expected ") + expected);
    const std::string& l = lines_[line_];
    size_t end = pos_;
    while (end < l.size() && !std::isspace(static_cast<unsigned char>(l[end]))) ++end;
    std::string tok = l.substr(pos_, end - pos_);
    token_line_ = line_;
    pos_ = end;
    return tok;
  }

  // The rest of the current line (after the last token), then moves to the next line.
  std::string rest_of_line() {
    if (line_ >= lines_.size()) fail("unexpected end of file");
    std::string r = lines_[line_].substr(std::min(pos_, lines_[line_].size()));
    token_line_ = line_;
    ++line_;
    pos_ = 0;
    return r;
  }

  double number(const char* what) {
    const std::string t = next(what);
    char* end = nullptr;
    const double v = std::strtod(t.c_str(), &end);
    if (end != t.c_str() + t.size() || t.empty()) fail(std::string("expected ") + what + ", got '" + t + "'");
    if (!std::isfinite(v)) fail(std::string(what) + " is not finite ('" + t + "')");
    return v;
  }

  long long integer(const char* what) {
    const std::string t = next(what);
    char* end = nullptr;
    const long long v = std::strtoll(t.c_str(), &end, 10);
    if (end != t.c_str() + t.size() || t.empty()) fail(std::string("expected ") + what + ", got '" + t + "'");
    return v;
  }

  long long count(const char* what, long long max = 100000000) {
    const long long n = integer(what);
    if (n < 0 || n > max) fail(std::string(what) + " out of range: " + std::to_string(n));
    return n;
  }

  void expect(const std::string& word) {
    const std::string t = next(word.c_str());
    if (t != word) fail("expected " + word + ", got '" + t + "'");
  }

  // Skips a section whose opening marker "$Name" was just read, up to "$EndName".
  void skip_section(const std::string& open) {
    const std::string close = "$End" + open.substr(1);
    while (next(close.c_str()) != close) {
    }
  }

  [[noreturn]] void fail(const std::string& message) const {
    throw Error(path_ + ":" + std::to_string(token_line_ + 1) + ": " + message);
  }
  size_t line() const { return token_line_ + 1; }

 private:
  void skip_space() {
    while (line_ < lines_.size()) {
      const std::string& l = lines_[line_];
      while (pos_ < l.size() && std::isspace(static_cast<unsigned char>(l[pos_]))) ++pos_;
      if (pos_ < l.size()) return;
      ++line_;
      pos_ = 0;
    }
  }

  std::string path_;
  std::vector<std::string> lines_;
  size_t line_ = 0, pos_ = 0, token_line_ = 0;
};

}  // namespace liver_sim
