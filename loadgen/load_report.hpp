// Report of a load run: a plain table for the terminal, JSON, and PNG plots
// (latency histogram, tiles received and holes over time, time to residency per cut).
#pragma once
#include <string>

#include "loadgen/load_run.hpp"

namespace st::loadgen {

std::string load_table(const LoadResult& r);
std::string load_json(const LoadResult& r);  // pretty-printed
// Writes load.json, load.txt, load_latency.png, load_timeline.png, load_cuts.png into
// `dir` (created). Throws st::Error naming the file on I/O failure.
void write_load_report(const LoadResult& r, const std::string& dir);

}  // namespace st::loadgen
