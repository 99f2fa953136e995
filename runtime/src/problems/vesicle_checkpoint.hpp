// Checkpoints of a vesicle schedule: after every converged stage that is kept, the stage's solution
// (NAME_stage_K.h5, + .xmf for ParaView) and the schedule so far (NAME_stages.json: every finished
// stage's record, which stage later ones continue from, the start's topology, the warnings). `lmeform run
// --restart` resumes with the next stage, on any number of ranks: a 3D schedule of several
// one-hour solves survives the loss of its machine.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>

#include <mpi.h>

#include "lmeform/level_set_topology.hpp"
#include "vesicle.hpp"

namespace lmeform::problems {

struct VesicleCheckpoint {
  std::filesystem::path directory;  ///< "": no checkpoints
  std::string scene_name;           ///< names the files
  bool restart = false;             ///< resume from the checkpoint in `directory`
};

/// What a checkpoint restores: the finished stages (records; the fields of the stages a later
/// stage can continue from) and the index of the stage the schedule continues from.
struct ResumedSchedule {
  VesicleRun run;
  std::size_t main_stage = 0;
};

/// Writes the last stage of `run` (its fields, collectively) and then the schedule file (rank 0,
/// atomically): a checkpoint never names a stage whose file is incomplete. Collective over comm.
void write_vesicle_checkpoint(MPI_Comm comm, const VesicleCheckpoint& checkpoint, const VesicleRun& run, std::size_t main_stage);

/// Reads the checkpoint of `checkpoint.directory` back for the schedule of `model`. Throws
/// std::runtime_error naming the file when it is missing or belongs to another scene or schedule,
/// or when every stage of the schedule is already in it. Collective over comm (the stage files are
/// read by blocks of rows).
[[nodiscard]] ResumedSchedule read_vesicle_checkpoint(MPI_Comm comm, const VesicleCheckpoint& checkpoint, const VesicleModel& model,
                                                      LevelSetGeometry geometry);

}  // namespace lmeform::problems
