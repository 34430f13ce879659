// The in-memory channel pair.
#include "proto/message_channel.h"

namespace headcast {
namespace {

// One direction: a queue that ends when its writer closes it or either end cancels.
template <typename T>
class Pipe {
 public:
  bool Push(const T& m) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (closed_ || cancelled_) return false;
    queue_.push_back(m);
    cv_.notify_all();
    return true;
  }
  bool Pop(T* m) {
    std::unique_lock<std::mutex> lock(mutex_);
    cv_.wait(lock, [&] { return !queue_.empty() || closed_ || cancelled_; });
    if (cancelled_ || queue_.empty()) return false;
    *m = std::move(queue_.front());
    queue_.pop_front();
    return true;
  }
  void Close() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
    cv_.notify_all();
  }
  void Cancel() {
    std::lock_guard<std::mutex> lock(mutex_);
    cancelled_ = true;
    queue_.clear();
    cv_.notify_all();
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<T> queue_;
  bool closed_ = false, cancelled_ = false;
};

struct Pipes {
  Pipe<v1::Uplink> up;
  Pipe<v1::Downlink> down;
  void Cancel() {
    up.Cancel();
    down.Cancel();
  }
};

class SenderEnd final : public UplinkChannel {
 public:
  explicit SenderEnd(std::shared_ptr<Pipes> p) : p_(std::move(p)) {}
  ~SenderEnd() override { p_->up.Close(); }
  bool Write(const v1::Uplink& m) override { return p_->up.Push(m); }
  bool Read(v1::Downlink* m) override { return p_->down.Pop(m); }
  void CloseWrites() override { p_->up.Close(); }
  void Cancel() override { p_->Cancel(); }

 private:
  std::shared_ptr<Pipes> p_;
};

class ReceiverEnd final : public DownlinkChannel {
 public:
  ReceiverEnd(std::shared_ptr<Pipes> p, std::string token) : p_(std::move(p)), token_(std::move(token)) {}
  ~ReceiverEnd() override { p_->down.Close(); }
  bool Write(const v1::Downlink& m) override { return p_->down.Push(m); }
  bool Read(v1::Uplink* m) override { return p_->up.Pop(m); }
  void CloseWrites() override { p_->down.Close(); }
  void Cancel() override { p_->Cancel(); }
  std::string bearer_token() const override { return token_; }

 private:
  std::shared_ptr<Pipes> p_;
  std::string token_;
};

}  // namespace

InMemoryChannelPair MakeInMemoryChannelPair(std::string bearer_token) {
  auto pipes = std::make_shared<Pipes>();
  return {std::make_unique<SenderEnd>(pipes), std::make_unique<ReceiverEnd>(pipes, std::move(bearer_token))};
}

}  // namespace headcast
