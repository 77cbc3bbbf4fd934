// The HTML page of a run: `shadowtile load --report`, `report` and `build --report` hand
// the JSON they wrote to scripts/html_report.py (matplotlib; installed beside the
// executable as share/shadowtile/html_report.py), which writes one self-contained page.
// The table and JSON are the command's real output; the page is extra: when python3 or
// matplotlib is missing, or SHADOWTILE_HTML=0, the command still succeeds and says in
// one line that the page was skipped and why.
#pragma once
#include <string>

namespace st::cli {

// Runs `python3 html_report.py KIND INPUT -o OUT --command "<this process's argv>"`
// (bounded: killed after 300 s) and prints, as the command's last line, either
// "html: OUT" or "html: skipped (WHY)". Never throws; returns whether OUT was written.
bool write_html_page(const std::string& kind, const std::string& input, const std::string& out);

// This process's command line (/proc/self/cmdline), quoted where a shell would need it.
std::string command_line();

}  // namespace st::cli
