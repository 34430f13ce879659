// c10d / Gloo all-reduce of gradients.
#include "training/data_parallel.h"

#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>

#include "common/core/options.h"

namespace headcast {

void DistributedOptions::Check() const {
  OptionsCheck c("DistributedOptions");
  c.InRange("world_size", world_size, 1, 4096).InRange("rank", rank, 0, world_size - 1);
  c.InRange("master_port", master_port, 1, 65535).InRange("timeout_s", timeout_s, 1, 86400);
  c.That(!master_addr.empty(), "master_addr is required");
  c.ThrowIfErrors();
}

struct GradientAllReduce::Impl {
  c10::intrusive_ptr<c10d::ProcessGroupGloo> group;
};

GradientAllReduce::GradientAllReduce(const DistributedOptions& o) : impl_(std::make_unique<Impl>()) {
  o.Check();
  const std::string where = o.master_addr + ":" + std::to_string(o.master_port);
  try {
    c10d::TCPStoreOptions store_options;
    store_options.port = static_cast<std::uint16_t>(o.master_port);
    store_options.isServer = o.rank == 0;
    store_options.numWorkers = static_cast<size_t>(o.world_size);
    store_options.timeout = std::chrono::seconds(o.timeout_s);
    auto store = c10::make_intrusive<c10d::TCPStore>(o.master_addr, store_options);
    auto options = c10d::ProcessGroupGloo::Options::create();
    options->timeout = std::chrono::seconds(o.timeout_s);
    options->devices.push_back(c10d::ProcessGroupGloo::createDeviceForHostname(o.master_addr));
    impl_->group = c10::make_intrusive<c10d::ProcessGroupGloo>(store, o.rank, o.world_size, options);
  } catch (const std::exception& e) {
    throw std::runtime_error("data-parallel group at " + where + " (rank " + std::to_string(o.rank) + " of " +
                             std::to_string(o.world_size) + "): " + std::string(e.what()).substr(0, 300));
  }
}

GradientAllReduce::~GradientAllReduce() = default;

void GradientAllReduce::SumGradients(const std::vector<torch::Tensor>& params) {
  std::vector<torch::Tensor> flat;
  for (const auto& p : params) flat.push_back(p.grad().defined() ? p.grad().reshape(-1) : torch::zeros({p.numel()}));
  std::vector<torch::Tensor> all = {torch::cat(flat)};
  impl_->group->allreduce(all)->wait();
  int64_t at = 0;
  torch::NoGradGuard no_grad;
  for (const auto& p : params) {
    torch::Tensor summed = all[0].narrow(0, at, p.numel()).view_as(p);
    at += p.numel();
    if (p.grad().defined())
      p.mutable_grad().copy_(summed);
    else
      p.mutable_grad() = summed.clone();
  }
}

double GradientAllReduce::Sum(double value) {
  std::vector<torch::Tensor> t = {torch::tensor({value}, torch::kFloat64)};
  impl_->group->allreduce(t)->wait();
  return t[0].item<double>();
}

void GradientAllReduce::Barrier() { impl_->group->barrier()->wait(); }

}  // namespace headcast
