// `shadowtile build ... --mpi` under mpirun: the map's cells spread over the ranks of an
// MPI job (OpenMPI). Every rank loads the scene and traces and encodes cells with all its
// threads; rank 0 also owns the pack: it plans the cells (skipping those a resumed .tmp
// holds), hands them out on request (dynamic scheduling: a rank that finishes early asks
// again), appends the journal bytes the ranks send back (each record checked as for a
// part file) and finishes the pack. Only rank 0 touches files.
//
// Failure: a rank that fails sends rank 0 its error, which names the rank and host and
// aborts the job (MPI_Abort); a rank that is killed makes mpirun end the job. Either way
// the pack is never finished: OUT.tmp keeps every appended cell for `--mpi --resume`.
#pragma once
#include <optional>
#include <string>

#include "tiles/bake/map_build.hpp"

namespace st::cli {

// Per-rank figures rank 0 prints after the build.
struct MpiBuildFigures {
  int ranks = 0;
  std::vector<uint64_t> cells_by_rank;  // rank 0's own threads included
  uint64_t bytes_received = 0;          // journal bytes sent to rank 0 by the others
};

// Runs the build on every rank (call it on all of them, after MPI is initialized by
// it). Returns rank 0's report and figures; nullopt on the other ranks. Errors on rank 0
// are printed and abort the job; never returns on failure.
std::optional<std::pair<MapBuildReport, MpiBuildFigures>> build_map_mpi(const Scene& scene, const LightSpace& light,
                                                                        MapBuildOptions options,
                                                                        const std::string& out_path);

// Rank of this process in MPI_COMM_WORLD once initialized (0 before).
int mpi_rank();
// Initializes MPI (MPI_THREAD_SERIALIZED); st::Error if the library cannot provide it.
void mpi_init(int* argc, char*** argv);

}  // namespace st::cli
