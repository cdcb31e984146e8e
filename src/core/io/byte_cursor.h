// A read position in a file held in memory, for readers whose formats mix text and binary
// (STL, PLY, legacy VTK): tokens, lines and raw little- or big-endian values, every read
// bounded by the end of the data. Errors throw FormatError naming the source and the line (text)
// or byte offset (binary). Internal to the core library; the public readers turn FormatError into
// their own error type.
#pragma once

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>

namespace liver_sim {

class FormatError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class ByteCursor {
 public:
  ByteCursor(const std::string& data, const std::string& origin) : data_(data), origin_(origin) {}

  size_t position() const { return pos_; }
  size_t remaining() const { return data_.size() - pos_; }
  bool at_end() {
    skip_space();
    return pos_ >= data_.size();
  }

  // The next run of non-space characters ("" at the end of the data).
  std::string token() {
    skip_space();
    token_start_ = pos_;
    while (pos_ < data_.size() && !std::isspace(static_cast<unsigned char>(data_[pos_]))) ++pos_;
    return data_.substr(token_start_, pos_ - token_start_);
  }
  std::string token(const char* expected) {
    std::string t = token();
    if (t.empty()) fail(std::string("unexpected end of file, expected ") + expected);
    return t;
  }
  // The next token, without moving.
  std::string peek() {
    const size_t pos = pos_, start = token_start_;
    std::string t = token();
    pos_ = pos;
    token_start_ = start;
    return t;
  }
  void expect(const std::string& word) {
    const std::string t = token(word.c_str());
    if (t != word) fail("expected " + word + ", got '" + t + "'");
  }
  // The rest of the current line, without its end; the cursor moves to the next line.
  std::string line() {
    token_start_ = pos_;
    const size_t end = std::min(data_.find('\n', pos_), data_.size());
    std::string l = data_.substr(pos_, end - pos_);
    if (!l.empty() && l.back() == '\r') l.pop_back();
    pos_ = std::min(end + 1, data_.size());
    return l;
  }
  // After the last token of a header line before binary data: the single line end that follows.
  void skip_line_end() {
    while (pos_ < data_.size() && (data_[pos_] == ' ' || data_[pos_] == '\t' || data_[pos_] == '\r')) ++pos_;
    if (pos_ < data_.size() && data_[pos_] == '\n') ++pos_;
  }

  double number(const char* what) {
    const std::string t = token(what);
    char* end = nullptr;
    const double v = std::strtod(t.c_str(), &end);
    if (end != t.c_str() + t.size()) fail(std::string("expected ") + what + ", got '" + t + "'");
    if (!std::isfinite(v)) fail(std::string(what) + " is not finite ('" + t + "')");
    return v;
  }
  long long integer(const char* what) {
    const std::string t = token(what);
    char* end = nullptr;
    errno = 0;
    const long long v = std::strtoll(t.c_str(), &end, 10);
    if (end != t.c_str() + t.size() || errno == ERANGE) fail(std::string("expected ") + what + ", got '" + t + "'");
    return v;
  }
  // A non-negative count no larger than `max`.
  long long count(const char* what, long long max) {
    const long long n = integer(what);
    if (n < 0 || n > max) fail(std::string(what) + " out of range: " + std::to_string(n));
    return n;
  }

  // `n` raw bytes.
  const char* bytes(size_t n, const char* what) {
    if (n > remaining()) {
      token_start_ = pos_;
      fail(std::string("file ends inside ") + what + " (" + std::to_string(n) + " bytes needed, " +
           std::to_string(remaining()) + " left)");
    }
    const char* p = data_.data() + pos_;
    pos_ += n;
    return p;
  }
  // One binary value of `size` bytes (1, 2, 4, 8), byte order given; integers as their value,
  // floats when `floating`.
  double binary(int size, bool floating, bool is_signed, bool big_endian, const char* what) {
    const char* p = bytes(static_cast<size_t>(size), what);
    unsigned char b[8];
    for (int i = 0; i < size; ++i) b[i] = static_cast<unsigned char>(p[big_endian ? size - 1 - i : i]);
    uint64_t u = 0;
    for (int i = size - 1; i >= 0; --i) u = (u << 8) | b[i];
    if (floating) {
      if (size == 4) {
        float f;
        const uint32_t u32 = static_cast<uint32_t>(u);
        std::memcpy(&f, &u32, 4);
        return f;
      }
      double d;
      std::memcpy(&d, &u, 8);
      return d;
    }
    if (!is_signed || size == 8) return is_signed ? static_cast<double>(static_cast<int64_t>(u)) : static_cast<double>(u);
    const uint64_t sign = uint64_t{1} << (8 * size - 1);
    return static_cast<double>(static_cast<int64_t>(u ^ sign) - static_cast<int64_t>(sign));
  }

  // Throws FormatError "origin:line N: message" after a text read, "origin: byte N: message"
  // after a binary one.
  [[noreturn]] void fail(const std::string& message) const {
    const size_t at = std::min(token_start_, data_.size());
    if (binary_) throw FormatError(origin_ + ": byte " + std::to_string(at) + ": " + message);
    const long long line = 1 + std::count(data_.begin(), data_.begin() + static_cast<std::ptrdiff_t>(at), '\n');
    throw FormatError(origin_ + ":" + std::to_string(line) + ": " + message);
  }
  // Messages count bytes instead of lines from here on (a binary body).
  void set_binary(bool binary) { binary_ = binary; }
  void mark() { token_start_ = pos_; }

 private:
  void skip_space() {
    while (pos_ < data_.size() && std::isspace(static_cast<unsigned char>(data_[pos_]))) ++pos_;
  }

  const std::string& data_;
  std::string origin_;
  size_t pos_ = 0, token_start_ = 0;
  bool binary_ = false;
};

}  // namespace liver_sim
