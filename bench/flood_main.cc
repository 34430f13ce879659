// headcast-flood: a bounded flood against a running receiver (loopback only),
// to show that threads and memory stay bounded and that a real sender still
// gets on screen. bench/flood.sh starts the receiver with its defaults, runs
// this, and reads the receiver's threads, RSS and shown senders.
//   - `--mute N` streams open and never say Hello;
//   - `--idle N` streams say Hello with a valid token, then nothing (those
//     over the session limit should get BUSY);
//   - after `--legit-after` seconds, one real sender (SenderClient, name
//     "legit") streams synthetic frames until the end.
// Prints a JSON report: how the flood's streams ended (gRPC status or Reject
// reason, counted), when the legit sender was welcomed, and the receiver's
// thread and RSS peaks sampled from /proc.
#include <grpcpp/grpcpp.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "common/codec/param_codec.h"
#include "common/core/log.h"
#include "common/core/options.h"
#include "common/core/program.h"
#include "common/core/timer.h"
#include "common/core/version.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/synthetic_motion.h"
#include "proto/convert.h"
#include "proto/headcast.grpc.pb.h"
#include "proto/protocol.h"
#include "sender/session_client.h"

namespace headcast {
namespace {

struct FloodOptions {
  std::string target, token;
  int mute = 300, idle = 50, channels = 10, receiver_pid = 0;
  double legit_after_s = 2, duration_s = 45;
  void Check() const {
    OptionsCheck c("flood");
    c.That(IsLoopbackAddress(target), "the flood only runs against a loopback address");
    c.InRange("mute", mute, 0, 1000).InRange("idle", idle, 0, 200).InRange("channels", channels, 1, 100);
    c.InRange("duration_s", duration_s, 1, 600).InRange("legit_after_s", legit_after_s, 0, duration_s);
    c.ThrowIfErrors();
  }
};

// Counts how streams ended, by a short label.
class Outcomes {
 public:
  void Add(const std::string& label) {
    std::lock_guard<std::mutex> lock(mutex_);
    ++counts_[label];
  }
  nlohmann::json Json() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return counts_;
  }

 private:
  mutable std::mutex mutex_;
  std::map<std::string, int> counts_;
};

std::string StatusLabel(const grpc::Status& s) {
  static const std::map<grpc::StatusCode, std::string> names = {{grpc::OK, "OK"},
                                                                {grpc::CANCELLED, "CANCELLED"},
                                                                {grpc::DEADLINE_EXCEEDED, "DEADLINE_EXCEEDED"},
                                                                {grpc::RESOURCE_EXHAUSTED, "RESOURCE_EXHAUSTED"},
                                                                {grpc::UNAVAILABLE, "UNAVAILABLE"},
                                                                {grpc::UNAUTHENTICATED, "UNAUTHENTICATED"}};
  const auto it = names.find(s.error_code());
  return it == names.end() ? "status " + std::to_string(s.error_code()) : it->second;
}

// One raw stream: optionally a Hello, then silence until the receiver ends it
// (or the run's deadline does).
void RawStream(v1::Headcast::Stub& stub, const FloodOptions& o, const v1::Uplink* hello, Outcomes* outcomes) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::duration_cast<std::chrono::milliseconds>(
                                                              std::chrono::duration<double>(o.duration_s)));
  context.AddMetadata("authorization", "Bearer " + o.token);
  auto stream = stub.Session(&context);
  std::string label;
  if (hello && stream->Write(*hello)) {
    v1::Downlink d;
    if (stream->Read(&d)) {
      if (d.has_reject()) label = "reject " + v1::Reject::Reason_Name(d.reject().reason());
      if (d.has_welcome()) label = "welcomed, then ";
      while (stream->Read(&d)) {
      }
    }
  } else if (!hello) {
    v1::Downlink d;
    while (stream->Read(&d)) {
    }
  }
  const grpc::Status status = stream->Finish();
  outcomes->Add(label.rfind("reject", 0) == 0 ? label : label + StatusLabel(status));
}

// Threads and resident memory of a process, from /proc.
struct ProcSample {
  int threads = 0;
  double rss_mb = 0;
};
ProcSample SampleProc(int pid) {
  ProcSample s;
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("Threads:", 0) == 0) s.threads = std::stoi(line.substr(8));
    if (line.rfind("VmRSS:", 0) == 0) s.rss_mb = std::stod(line.substr(6)) / 1024;  // kB
  }
  return s;
}

int Run(const FloodOptions& o) {
  InitLogging("");
  o.Check();
  const HeadModel model = MakeBuiltinHead();
  const CodecLayout layout = CodecLayout::FromModel(model);
  v1::Uplink hello;
  hello.mutable_hello()->set_protocol_version(kProtocolVersion);
  hello.mutable_hello()->set_avatar_id("demo");
  hello.mutable_hello()->set_sender_name("idle flood");
  ToProto(layout, 30, hello.mutable_hello()->mutable_layout());

  std::vector<std::unique_ptr<v1::Headcast::Stub>> stubs;
  for (int i = 0; i < o.channels; ++i) {
    grpc::ChannelArguments args;
    args.SetInt("grpc.channel_id", i);  // distinct connections, not one shared subchannel
    stubs.push_back(
        v1::Headcast::NewStub(grpc::CreateCustomChannel(o.target, grpc::InsecureChannelCredentials(), args)));
  }
  Stopwatch clock;
  std::atomic<bool> done{false};
  ProcSample peak, before = o.receiver_pid ? SampleProc(o.receiver_pid) : ProcSample{};
  std::thread sampler([&] {
    while (!done && o.receiver_pid) {
      const ProcSample s = SampleProc(o.receiver_pid);
      peak.threads = std::max(peak.threads, s.threads);
      peak.rss_mb = std::max(peak.rss_mb, s.rss_mb);
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  });
  Outcomes mute, idle;
  std::vector<std::thread> streams;
  // The authenticated sessions first, so they take the session slots (and the
  // rest get BUSY), then the streams that never say Hello.
  for (int i = 0; i < o.idle; ++i)
    streams.emplace_back([&, i] { RawStream(*stubs[i % o.channels], o, &hello, &idle); });
  std::this_thread::sleep_for(std::chrono::seconds(1));
  for (int i = 0; i < o.mute; ++i)
    streams.emplace_back([&, i] { RawStream(*stubs[i % o.channels], o, nullptr, &mute); });
  std::this_thread::sleep_for(std::chrono::duration<double>(std::max(0.0, o.legit_after_s - 1)));
  SenderOptions so;
  so.target = o.target;
  so.plaintext = true;
  so.token = o.token;
  so.avatar_id = "demo";
  so.sender_name = "legit";
  SenderClient legit(so, layout);
  const double legit_started = clock.ElapsedSeconds();
  legit.Start();
  double welcomed_after = -1;
  for (int i = 0; clock.ElapsedSeconds() < o.duration_s; ++i) {
    FrameParams f = SyntheticTalkingHead(model, i);
    f.sequence = i;
    f.capture_time_s = SteadyNowSeconds();
    legit.Submit(f);
    if (welcomed_after < 0 && legit.counters().streaming) welcomed_after = clock.ElapsedSeconds() - legit_started;
    std::this_thread::sleep_for(std::chrono::milliseconds(33));
  }
  legit.Stop("flood over");
  const ProcSample during = o.receiver_pid ? SampleProc(o.receiver_pid) : ProcSample{};
  for (auto& t : streams) t.join();
  done = true;
  sampler.join();
  const SenderCounters lc = legit.counters();
  const nlohmann::json report = {{"mute_streams", o.mute},
                                 {"idle_sessions", o.idle},
                                 {"mute_outcomes", mute.Json()},
                                 {"idle_outcomes", idle.Json()},
                                 {"legit_started_s", legit_started},
                                 {"legit_welcomed_after_s", welcomed_after},
                                 {"legit_frames_sent", lc.sent},
                                 {"legit_busy_rejections", lc.rejections},
                                 {"receiver_threads_before", before.threads},
                                 {"receiver_threads_peak", peak.threads},
                                 {"receiver_threads_at_end", during.threads},
                                 {"receiver_rss_mb_before", before.rss_mb},
                                 {"receiver_rss_mb_peak", peak.rss_mb},
                                 {"receiver_rss_mb_at_end", during.rss_mb},
                                 {"seconds", clock.ElapsedSeconds()}};
  std::cout << report.dump(2) << "\n";
  return 0;
}

}  // namespace
}  // namespace headcast

int main(int argc, char** argv) {
  CLI::App app{"headcast-flood: a bounded stream flood against a loopback receiver"};
  headcast::AddVersionFlag(app);
  headcast::AddConfigFile(app);
  app.fallthrough();  // global flags (--log, --config) after a subcommand too
  headcast::FloodOptions o;
  app.add_option("--target", o.target, "the receiver, host:port (loopback)")->required();
  app.add_option("--token", o.token, "a token the receiver accepts")->required();
  app.add_option("--mute", o.mute, "streams that never say Hello")->capture_default_str();
  app.add_option("--idle", o.idle, "authenticated sessions that say Hello, then nothing")->capture_default_str();
  app.add_option("--channels", o.channels, "connections the flood's streams share")->capture_default_str();
  app.add_option("--legit-after", o.legit_after_s, "start the real sender after this many seconds")
      ->capture_default_str();
  app.add_option("--duration", o.duration_s, "the whole run, seconds")->capture_default_str();
  app.add_option("--receiver-pid", o.receiver_pid, "sample this process's threads and RSS");
  return headcast::RunProgram(app, argc, argv, [&] { return headcast::Run(o); });
}
