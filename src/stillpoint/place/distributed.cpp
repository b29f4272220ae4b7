#include "stillpoint/place/distributed.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdlib>
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>

#include "stillpoint/common/error.hpp"

namespace sp::place {

namespace {

std::string message_of(const std::exception& e) {
  if (const auto* c = dynamic_cast<const c10::Error*>(&e)) return c->what_without_backtrace();
  return e.what();
}

bool is_loopback(const std::string& host) { return host == "localhost" || host.rfind("127.", 0) == 0; }

// Gloo's own socket, on the interface the other ranks can reach. GLOO_SOCKET_IFNAME wins, as in
// PyTorch; a loopback master means a single machine; otherwise the address of this machine's name.
std::shared_ptr<gloo::transport::Device> make_device(const std::string& master_addr) {
  if (const char* ifname = std::getenv("GLOO_SOCKET_IFNAME"); ifname && *ifname)
    return c10d::ProcessGroupGloo::createDeviceForInterface(ifname);
  if (is_loopback(master_addr)) return c10d::ProcessGroupGloo::createDeviceForHostname("127.0.0.1");
  return c10d::ProcessGroupGloo::createDefaultDevice();
}

}  // namespace

void validate(const DistOptions& o) {
  if (o.world_size < 1) throw sp::Error(fmt::format("world size must be at least 1, not {}", o.world_size));
  if (o.rank < 0 || o.rank >= o.world_size)
    throw sp::Error(fmt::format("rank {} is outside [0, {}): ranks count from 0 to world size - 1", o.rank,
                                o.world_size));
  if (o.world_size > 1) {
    if (o.master_addr.empty()) throw sp::Error("distributed training needs the master's address (--master)");
    if (o.master_port < 1 || o.master_port > 65535)
      throw sp::Error(fmt::format("master port {} is outside [1, 65535]", o.master_port));
    if (o.timeout_s <= 0) throw sp::Error("distributed timeout must be positive");
  }
}

struct ProcessGroup::Impl {
  c10::intrusive_ptr<c10d::Store> store;
  c10::intrusive_ptr<c10d::ProcessGroupGloo> pg;
};

ProcessGroup::ProcessGroup(const DistOptions& o) : opts_(o) {
  validate(o);
  if (o.world_size == 1) return;
  const auto timeout = std::chrono::milliseconds(static_cast<int64_t>(o.timeout_s * 1000));
  impl_ = std::make_unique<Impl>();
  const std::string where = fmt::format("{}:{}", o.master_addr, o.master_port);
  try {
    c10d::TCPStoreOptions so;
    so.port = static_cast<std::uint16_t>(o.master_port);
    so.isServer = o.rank == 0;
    so.numWorkers = o.world_size;
    so.waitWorkers = true;  // rank 0 returns only once every rank has connected (or times out)
    so.timeout = timeout;
    impl_->store = c10::make_intrusive<c10d::TCPStore>(o.master_addr, so);
  } catch (const std::exception& e) {
    throw sp::Error(
        fmt::format("distributed training (rank {} of {}): rendezvous at {} failed within {} s: {} ({})",
                    o.rank, o.world_size, where, o.timeout_s,
                    o.rank == 0 ? "not every rank connected, or the port is taken"
                                : "rank 0 is not listening there, or not every rank started",
                    message_of(e)));
  }
  try {
    auto pgo = c10d::ProcessGroupGloo::Options::create(timeout);
    pgo->devices.push_back(make_device(o.master_addr));
    pgo->threads = 2;
    impl_->pg = c10::make_intrusive<c10d::ProcessGroupGloo>(impl_->store, o.rank, o.world_size, pgo);
  } catch (const std::exception& e) {
    throw sp::Error(fmt::format(
        "distributed training (rank {} of {}): rendezvous via {} failed: the ranks did "
        "not all connect within {} s (a rank died or cannot reach this one; set GLOO_SOCKET_IFNAME "
        "to the interface the machines share): {}",
        o.rank, o.world_size, where, o.timeout_s, message_of(e)));
  }
  spdlog::info("distributed training: rank {} of {} joined via {}", o.rank, o.world_size, where);
}

ProcessGroup::~ProcessGroup() = default;

void ProcessGroup::lost_rank(const char* what, const std::exception& e) const {
  throw sp::Error(
      fmt::format("distributed training (rank {} of {}): lost a rank during {}: another rank "
                  "died, stalled for more than {} s or dropped off the network ({})",
                  opts_.rank, opts_.world_size, what, opts_.timeout_s, message_of(e)));
}

void ProcessGroup::all_reduce(torch::Tensor& t, Op op, const char* what) {
  if (!impl_) return;
  std::vector<at::Tensor> ts{t};
  c10d::AllreduceOptions ao;
  ao.reduceOp = op == Op::Sum ? c10d::ReduceOp::SUM : c10d::ReduceOp::MAX;
  ao.timeout = std::chrono::milliseconds(static_cast<int64_t>(opts_.timeout_s * 1000));
  try {
    impl_->pg->allreduce(ts, ao)->wait();
  } catch (const std::exception& e) {
    lost_rank(what, e);
  }
}

void ProcessGroup::broadcast(torch::Tensor& t, int root, const char* what) {
  if (!impl_) return;
  std::vector<at::Tensor> ts{t};
  c10d::BroadcastOptions bo;
  bo.rootRank = root;
  bo.timeout = std::chrono::milliseconds(static_cast<int64_t>(opts_.timeout_s * 1000));
  try {
    impl_->pg->broadcast(ts, bo)->wait();
  } catch (const std::exception& e) {
    lost_rank(what, e);
  }
}

}  // namespace sp::place
