#pragma once
// Data-parallel plumbing for training (internal to sp_place: uses libtorch). A thin wrapper over
// libtorch's c10d: a TCPStore hosted by rank 0 for the rendezvous and a ProcessGroupGloo for the
// collectives. Every failure (a peer that died, stalled past the timeout or never joined) becomes an
// sp::Error that says so, instead of a hang or a bare gloo message.
#include <torch/torch.h>

#include <memory>
#include <string>

#include "stillpoint/place/dist_options.hpp"

namespace sp::place {

class ProcessGroup {
 public:
  enum class Op { Sum, Max };
  // Joins the group (blocks until all world_size ranks have joined, or throws after the timeout).
  explicit ProcessGroup(const DistOptions& o);
  ~ProcessGroup();
  ProcessGroup(const ProcessGroup&) = delete;
  ProcessGroup& operator=(const ProcessGroup&) = delete;

  [[nodiscard]] int rank() const { return opts_.rank; }
  [[nodiscard]] int size() const { return opts_.world_size; }
  // In place on a contiguous CPU tensor; `what` names the step in the error message.
  void all_reduce(torch::Tensor& t, Op op, const char* what);
  void broadcast(torch::Tensor& t, int root, const char* what);

 private:
  [[noreturn]] void lost_rank(const char* what, const std::exception& e) const;
  struct Impl;
  DistOptions opts_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sp::place
