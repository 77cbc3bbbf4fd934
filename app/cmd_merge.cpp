// shadowtile merge: part files of a sharded build (build --shard I/N) -> one pack.
#include <cstdio>

#include "app/command.hpp"
#include "common/error.hpp"
#include "tiles/encode/pack_merge.hpp"

namespace st::cli {
namespace {

struct MergeArgs {
  std::vector<std::string> parts;
  std::string out;
  bool quiet = false;
  std::string dagmh_dictionary = "on";
};

void run_merge(const MergeArgs& a) {
  if (a.dagmh_dictionary != "on" && a.dagmh_dictionary != "off")
    throw Error("--dagmh-dictionary: expected on or off, got '" + a.dagmh_dictionary + "'");
  MergeReport r = merge_parts(a.parts, a.out, a.dagmh_dictionary == "on");
  if (!a.quiet) {
    std::printf("merged %s: %u shards, %llu cells, %llu tiles, %.2f MiB of journal copied\n", a.out.c_str(),
                r.shard_count, (unsigned long long)r.cells, (unsigned long long)r.tiles,
                double(r.bytes_copied) / (1 << 20));
    if (r.dictionary_bytes)
      std::printf("  DAG-MH dictionary rebuilt over every part's tiles: %.1f KiB\n", double(r.dictionary_bytes) / 1024);
  }
}

void setup_merge(CLI::App& app) {
  auto a = std::make_shared<MergeArgs>();
  app.footer(
      "Example (a Slurm array or Kubernetes Indexed Job runs one build per index):\n"
      "  shadowtile build procedural:city --light sun:azimuth=30,elevation=50 --resolution 64k "
      "--shard $I/16 -o city.$I.part\n"
      "  shadowtile merge city.*.part -o city.pack\n"
      "Every shard 0..N-1 must be given once and be complete; every record's CRC is checked.");
  app.add_option("parts", a->parts, "Part files written by build --shard I/N (all N of them)")->required();
  app.add_option("-o,--output", a->out, "Pack file to write (built as OUT.tmp, renamed when complete)")
      ->required();
  app.add_option("--dagmh-dictionary", a->dagmh_dictionary,
                 "dagmh parts: on (default, as build) builds the pack-wide dictionary over all the parts' tiles; "
                 "off keeps every tile self-contained (match the one-go build's choice)")
      ->capture_default_str();
  app.add_flag("-q,--quiet", a->quiet, "No summary");
  app.callback([a]() { run_merge(*a); });
}

Register reg_merge{"merge", "Join the part files of a sharded build (build --shard I/N) into one pack", setup_merge};

}  // namespace
}  // namespace st::cli
