#include "lmeform/collective_error.hpp"

#include <array>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "lmeform/lme_basis.hpp"

namespace lmeform {

void throw_on_every_rank(MPI_Comm comm, const std::exception_ptr& local) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  int first = local ? rank : size;
  MPI_Allreduce(MPI_IN_PLACE, &first, 1, MPI_INT, MPI_MIN, comm);
  if (first == size) return;
  enum Kind : int { lme, invalid_argument, other };
  std::array<int, 4> header{other, 0, 0, 0};  // kind, LME reason, numbers, characters
  std::vector<double> numbers;                // LME: gradient norm, neighbours, the point
  std::string text;
  if (rank == first) {
    try {
      std::rethrow_exception(local);
    } catch (const LmeEvaluationError& e) {
      header[0] = lme;
      header[1] = static_cast<int>(e.reason());
      numbers = {e.gradient_norm(), static_cast<double>(e.neighbour_count())};
      numbers.insert(numbers.end(), e.point().begin(), e.point().end());
      text = e.detail();
    } catch (const std::invalid_argument& e) {
      header[0] = invalid_argument;
      text = e.what();
    } catch (const std::exception& e) {
      text = e.what();
    } catch (...) {
      text = "an unknown error";
    }
    header[2] = static_cast<int>(numbers.size());
    header[3] = static_cast<int>(text.size());
  }
  MPI_Bcast(header.data(), 4, MPI_INT, first, comm);
  numbers.resize(static_cast<std::size_t>(header[2]));
  text.resize(static_cast<std::size_t>(header[3]));
  if (header[2] > 0) MPI_Bcast(numbers.data(), header[2], MPI_DOUBLE, first, comm);
  if (header[3] > 0) MPI_Bcast(text.data(), header[3], MPI_CHAR, first, comm);
  if (rank == first) std::rethrow_exception(local);
  if (header[0] == lme)
    throw LmeEvaluationError(static_cast<LmeFailure>(header[1]), std::span<const double>(numbers).subspan(2),
                             static_cast<std::size_t>(numbers[1]), numbers[0], text);
  if (header[0] == invalid_argument) throw std::invalid_argument(text);
  throw std::runtime_error(text);
}

}  // namespace lmeform
