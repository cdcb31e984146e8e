// How a command-line tool in src/tools reads its options and writes its result.
//
// Options: the tool builds a CLI::App (CLI11) named after it, calls describe() with its usage
// lines and what its exit statuses mean, adds one option per setting (->option_text("FILE") for
// the value's name; add_overrides for --set, add_list for lists; the description states the
// unit, the default and the bounds, and a check enforces them: number, positive, integer,
// at_least, CLI::IsMember; rules between options go in app.callback() as a thrown
// CLI::ValidationError), then returns parse()'s status if it has one.
// --help prints the text on standard output and exits 0; a refused command line is one line on
// standard error naming the option and exits kBadCommandLine.
//
// Results: a JSON result is an nlohmann::ordered_json built in the order it is to be read and
// printed by print_json. CSV and tables stay each tool's own.
#pragma once

#include <CLI/CLI.hpp>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "liver_sim/runtime/worker_pool.h"

namespace liver_sim::tool {

constexpr int kBadCommandLine = 2;

// The help text: the tool's usage lines, what it does, its options, then `footer` (e.g. what its
// exit statuses mean).
class HelpFormatter : public CLI::Formatter {
 public:
  explicit HelpFormatter(std::string usage) : usage_(std::move(usage)) { column_width(24); }
  std::string make_help(const CLI::App* app, std::string, CLI::AppFormatMode mode) const override {
    const std::string footer = make_footer(app);
    return usage_ + make_description(app) + make_groups(app, mode) + (footer.empty() ? "" : "\n" + footer);
  }

 private:
  std::string usage_;
};

inline void describe(CLI::App& app, const std::string& usage, const std::string& footer = "") {
  app.formatter(std::make_shared<HelpFormatter>(usage));
  app.set_help_flag("-h,--help", "this text");
  if (!footer.empty()) app.footer(footer);
}

// The exit status when the tool is to stop here (0 after --help, kBadCommandLine after a refusal),
// else nothing: run.
inline std::optional<int> parse(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
    return std::nullopt;
  } catch (const CLI::CallForHelp&) {
    std::cout << app.help();
    return 0;
  } catch (const CLI::ParseError& e) {
    std::cerr << app.get_name() << ": " << e.what() << " (see " << app.get_name() << " --help)\n";
    return kBadCommandLine;
  }
}

// --set K=V, repeatable: scalars of the scene overridden, in the order given.
inline CLI::Option* add_overrides(CLI::App& app, std::vector<std::string>& overrides, const std::string& description) {
  return app.add_option("--set", overrides, description)->option_text("K=V")->allow_extra_args(false);
}

// An option whose value is a comma-separated list (`text` names it, e.g. "N,..."): one run per
// item, or one item each; given, it replaces the default list.
template <typename T>
CLI::Option* add_list(CLI::App& app, const std::string& name, const std::string& text, std::vector<T>& values,
                      const std::string& description) {
  return app.add_option(name, values, description)->option_text(text)->delimiter(',')->allow_extra_args(false);
}

// A finite number, read as strtod reads it, for which `within` holds (`bounds` says what it asks,
// e.g. "> 0"); NaN and infinities are refused (CLI11's own Range lets NaN through). The text is
// passed on in 17 digits, which CLI11's conversion (through long double) reads back as the same
// double.
inline CLI::Validator number(const std::string& bounds, std::function<bool(double)> within) {
  return CLI::Validator(
      [bounds, within](std::string& text) -> std::string {
        const char* begin = text.c_str();
        char* end = nullptr;
        const double x = std::strtod(begin, &end);
        if (end == begin || *end != '\0' || !std::isfinite(x)) return "'" + text + "' is not a finite number";
        if (!within(x)) return text + " is not " + bounds;
        char digits[32];
        std::snprintf(digits, sizeof digits, "%.17g", x);
        text = digits;
        return "";
      },
      "NUMBER");
}
inline CLI::Validator any_number() {
  return number("finite", [](double) { return true; });
}
inline CLI::Validator positive() {
  return number("> 0", [](double x) { return x > 0; });
}
inline CLI::Validator non_negative() {
  return number(">= 0", [](double x) { return x >= 0; });
}

// A whole number (that fits an int) for which `within` holds (`bounds` says what it asks).
inline CLI::Validator integer(const std::string& bounds, std::function<bool(long)> within) {
  return CLI::Validator(
      [bounds, within](std::string& text) -> std::string {
        const char* begin = text.c_str();
        char* end = nullptr;
        errno = 0;
        const long n = std::strtol(begin, &end, 10);
        if (end == begin || *end != '\0' || errno == ERANGE || n < INT_MIN || n > INT_MAX)
          return "'" + text + "' is not a whole number";
        return within(n) ? "" : text + " is not " + bounds;
      },
      "INTEGER");
}
inline CLI::Validator at_least(long low) {
  return integer(">= " + std::to_string(low), [low](long n) { return n >= low; });
}

// solver.threads, the element loops' threads: its bounds as the help says them, and its check.
inline std::string thread_bounds() { return "in [1, " + std::to_string(WorkerPool::kMaxThreads) + "]"; }
inline CLI::Validator thread_count() {
  return integer(thread_bounds(), [](long n) { return n >= 1 && n <= WorkerPool::kMaxThreads; });
}

// Prints a tool's JSON result: two-space indentation; a number that is not finite as null (JSON
// has no NaN or infinity); bytes that are not UTF-8 (a file name is bytes) as U+FFFD.
inline void print_json(std::ostream& out, const nlohmann::ordered_json& result) {
  out << result.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) << '\n';
}

}  // namespace liver_sim::tool
