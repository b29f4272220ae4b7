#pragma once
// Where and how a training process joins data-parallel training (torch-free: part of TrainOptions;
// the process group itself is distributed.hpp).
#include <string>

namespace sp::place {

struct DistOptions {
  int world_size = 1;  // processes training together; 1: no communication, every collective a no-op
  int rank = 0;        // [0, world_size); rank 0 hosts the rendezvous and alone writes files
  std::string master_addr = "127.0.0.1";  // rank 0's address
  int master_port = 29500;
  double timeout_s = 300;  // rendezvous and every collective: a rank silent this long fails the others
};

// Throws sp::Error for a world size < 1, a rank outside [0, world size), a port outside [1, 65535]
// or an empty master address.
void validate(const DistOptions& o);

}  // namespace sp::place
