// What a file's name says of its format.
#pragma once

#include <cctype>
#include <string>

namespace liver_sim {

// The extension of the file's name, lower-case and without its dot ("" when it has none; a dot
// in a folder's name is not one).
inline std::string file_extension(const std::string& path) {
  const size_t dot = path.rfind('.'), slash = path.rfind('/');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string e = path.substr(dot + 1);
  for (char& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

}  // namespace liver_sim
