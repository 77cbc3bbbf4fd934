// The benchmarks' command lines, written once over CLI11 (as the `shadowtile` CLI's options
// are): `--help` lists a bench's options with their defaults, and a bad option or value is one
// line on stderr ("bench_x: ...; --help lists the options") and exit status 2.
//
//   st::bench::Options opt("bench_x", "What it measures");
//   opt.value("--reps", reps, "Median of R runs")
//      .flag("--quick", quick, "A smaller run")
//      .with("--res", [&](const std::string& v) { level = parse_level(v); }, "Map side: 4k, 16k, ...");
//   opt.parse(argc, argv);  // exits after --help or a bad option
//
// An option given twice keeps its last value (as the hand-written loops before did), except
// `each` and `rest`, which keep every value in order. `with` and `value` callbacks run after the
// whole line is read, in the order the options were added, not the order they were given.
#pragma once
#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace st::bench {

class Options {
 public:
  explicit Options(std::string name, std::string description = "")
      : name_(name), app_(std::move(description), std::move(name)) {
    app_.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  }
  Options(const Options&) = delete;
  Options& operator=(const Options&) = delete;

  // --NAME VALUE read into `into` (a string or a number; "12x" or "-1" for an unsigned is refused).
  // `names` may list aliases: "--resolution,--resolutions". The help shows the default.
  template <class T>
  Options& value(const std::string& names, T& into, const std::string& help) {
    app_.add_option(names, into, help)->capture_default_str();
    return *this;
  }

  // --NAME (no value): sets `into` to `to` (true; false for a --no-X switch).
  Options& flag(const std::string& names, bool& into, const std::string& help, bool to = true) {
    app_.add_flag_callback(names, [&into, to] { into = to; }, help);
    return *this;
  }

  // --NAME VALUE handed to `read` (lists, checked words, specs parsed by the library); what `read`
  // throws becomes the one line. A std::stoul-style failure names the option and the value.
  Options& with(const std::string& names, std::function<void(const std::string&)> read, const std::string& help) {
    app_.add_option_function<std::string>(
        names,
        [names, read = std::move(read)](const std::string& v) {
          try {
            read(v);
          } catch (const std::logic_error&) {  // std::invalid_argument, std::out_of_range
            throw CLI::ValidationError(names, "cannot read '" + v + "'");
          }
        },
        help);
    return *this;
  }

  // --NAME VALUE, repeatable: every value, in order.
  Options& each(const std::string& names, std::vector<std::string>& into, const std::string& help) {
    app_.add_option(names, into, help)->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)->allow_extra_args(false);
    return *this;
  }

  // The positional arguments (PACK...): every one, in order.
  Options& rest(const std::string& name, std::vector<std::string>& into, const std::string& help) {
    app_.add_option(name, into, help)->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    return *this;
  }

  // Whether the line gave option `name` (after parse()): a --quick that yields to explicit values.
  bool given(const std::string& name) const { return app_.count(name) > 0; }

  // For what the helpers above do not cover (groups, exclusions).
  CLI::App& app() { return app_; }

  // Reads the command line. --help: prints the options and exits 0. A bad option or value: one
  // line on stderr, exit 2.
  void parse(int argc, char** argv) {
    try {
      app_.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
      if (e.get_exit_code() == 0) std::exit(app_.exit(e));  // --help
      fail(e.what());
    } catch (const std::exception& e) {
      fail(e.what());
    }
  }

  // A check after parse() (a range, a pair of options): the same one line and exit 2.
  [[noreturn]] void fail(const std::string& what) const {
    std::fprintf(stderr, "%s: %s; --help lists the options\n", name_.c_str(), what.c_str());
    std::exit(2);
  }

 private:
  std::string name_;
  CLI::App app_;
};

}  // namespace st::bench
