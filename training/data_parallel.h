// Data-parallel training across processes or machines (libtorch's c10d with
// the Gloo backend over TCP): every rank computes the gradients of its share of
// the batch, one all-reduce sums them, and every rank takes the same Adam step,
// so the weights stay identical — the same weights as one process running the
// whole batch, up to float summation order.
#pragma once

#include <torch/torch.h>

#include <memory>
#include <string>
#include <vector>

namespace headcast {

struct DistributedOptions {
  int rank = 0;        // this process, 0 .. world_size - 1; rank 0 hosts the TCP store and writes the outputs
  int world_size = 1;  // processes in all
  std::string master_addr = "127.0.0.1";  // rank 0's address (the store); Gloo binds to this host's interface for it
  int master_port = 29500;
  int timeout_s = 300;  // waiting for the others (start-up and every step)
  bool enabled() const { return world_size > 1; }
  void Check() const;
};

class GradientAllReduce {
 public:
  // Blocks until all ranks have joined; throws with the address on failure or timeout.
  explicit GradientAllReduce(const DistributedOptions& options);
  ~GradientAllReduce();
  // Sums the gradients of `params` over all ranks, in place (a missing gradient counts as zero).
  void SumGradients(const std::vector<torch::Tensor>& params);
  double Sum(double value);
  // Waits for every rank.
  void Barrier();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace headcast
