// Where a tool finds the package's own files (config/scenes/...), at run time from where the
// tool itself is, so that no path of the build machine is compiled in and an install space runs
// with the sources gone. A tool is <prefix>/lib/liver_sim/<tool>, in an install space or a devel
// space: the install space has the files in <prefix>/share/liver_sim (its package.xml beside
// them); a devel space names its source folders in <prefix>/.catkin, where the package is the
// folder whose package.xml names it (as catkin's find_in_workspaces reads them).
#pragma once

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <system_error>

namespace liver_sim::tool {

namespace detail {

inline bool names_package(const std::filesystem::path& package_xml) {
  std::ifstream in(package_xml);
  std::stringstream text;
  text << in.rdbuf();
  return text.str().find("<name>liver_sim</name>") != std::string::npos;
}

// The folder of package liver_sim under a devel space's source folder, or empty.
inline std::filesystem::path package_in_sources(const std::filesystem::path& sources) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::exists(sources / "package.xml", ec)) return names_package(sources / "package.xml") ? sources : fs::path();
  for (fs::recursive_directory_iterator it(sources, fs::directory_options::skip_permission_denied, ec), end;
       !ec && it != end; it.increment(ec)) {
    if (!it->is_directory(ec)) continue;
    const fs::path dir = it->path();
    const std::string name = dir.filename().string();
    // Packages do not nest; catkin skips hidden folders and those marked CATKIN_IGNORE.
    if ((!name.empty() && name[0] == '.') || fs::exists(dir / "CATKIN_IGNORE", ec)) {
      it.disable_recursion_pending();
    } else if (fs::exists(dir / "package.xml", ec)) {
      if (names_package(dir / "package.xml")) return dir;
      it.disable_recursion_pending();
    }
  }
  return {};
}

}  // namespace detail

// The package's file `relative` (e.g. "config/scenes/probe_cube.yaml"): in the install space or
// the devel space's sources of the running tool. Not found, the install space's path, which the
// loader then names as the file it cannot open.
inline std::string package_file(const std::string& relative) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path prefix = fs::canonical("/proc/self/exe", ec).parent_path().parent_path().parent_path();
  const fs::path share = prefix / "share" / "liver_sim";
  if (fs::exists(share / "package.xml", ec)) return (share / relative).string();
  std::ifstream marker(prefix / ".catkin");
  std::string sources;
  while (std::getline(marker, sources, ';')) {
    while (!sources.empty() && (sources.back() == '\n' || sources.back() == ' ')) sources.pop_back();
    if (sources.empty()) continue;
    const fs::path package = detail::package_in_sources(sources);
    if (!package.empty()) return (package / relative).string();
  }
  return (share / relative).string();
}

}  // namespace liver_sim::tool
