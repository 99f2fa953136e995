// An error raised on some ranks of a collective phase, raised on all of them.
#pragma once

#include <exception>

#include <mpi.h>

namespace lmeform {

/// Collective over `comm`: when no rank passes an exception, returns on every rank. Otherwise every
/// rank throws the error of the lowest rank that passed one — that rank rethrows its own; the
/// others a copy of the same type and message (LmeEvaluationError with its reason, point and
/// neighbour count; std::invalid_argument; any other as std::runtime_error). For work that can fail
/// on one rank only (its own elements), so that no rank is left waiting in the next collective call.
void throw_on_every_rank(MPI_Comm comm, const std::exception_ptr& local);

}  // namespace lmeform
