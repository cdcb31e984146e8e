// JSON text for the command-line tools' standard output.
#pragma once

#include <string>

namespace liver_sim {

// A JSON string literal: quotes, backslashes and newlines escaped.
inline std::string json_string(const std::string& text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') out += '\\';
    if (c == '\n') {
      out += "\\n";
      continue;
    }
    out += c;
  }
  return out + "\"";
}

}  // namespace liver_sim
