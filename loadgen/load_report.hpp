// Report of a load run: a plain table for the terminal and JSON (with the time series and
// the latency percentile curve the HTML page, scripts/html_report.py, draws).
#pragma once
#include <string>

#include "loadgen/load_run.hpp"

namespace st::loadgen {

std::string load_table(const LoadResult& r);
std::string load_json(const LoadResult& r);  // pretty-printed
// Writes load.json and load.txt into `dir` (created). Throws st::Error naming the file on I/O failure.
void write_load_report(const LoadResult& r, const std::string& dir);

}  // namespace st::loadgen
