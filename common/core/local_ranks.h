// Copies of this program as the ranks of a data-parallel run on one machine:
// this process becomes rank 0 of N and starts ranks 1..N-1 as copies of
// itself, told their rank and a free loopback port, each with one compute
// thread (headcast-train --processes N; on two cores two single-threaded
// ranks beat one process with two threads: bench/DEFAULTS.md). Programs use
// it; libraries never start processes.
#pragma once

#include <sys/types.h>

#include <atomic>
#include <string>
#include <thread>
#include <vector>

namespace headcast {

class LocalRanks {
 public:
  // `args`: this program's arguments after argv[0]; the copies get them plus
  // --processes 1 --threads 1 --rank R --world-size N --master-addr 127.0.0.1
  // --master-port P (a free loopback port). Their stdout goes to /dev/null
  // (rank 0 reports); their stderr is this one's. Throws when one cannot start.
  LocalRanks(int processes, const std::vector<std::string>& args);
  // Kills and reaps copies still running (rank 0 failed).
  ~LocalRanks();
  LocalRanks(const LocalRanks&) = delete;
  LocalRanks& operator=(const LocalRanks&) = delete;

  int port() const { return port_; }
  // After rank 0's work: waits for the copies; throws naming a rank that failed.
  void Wait();

 private:
  void Watch();
  int port_ = 0;
  std::vector<pid_t> children_;
  std::vector<int> failed_;  // ranks that exited with an error (set by the watcher)
  std::atomic<bool> stopping_{false};
  std::thread watcher_;
};

// In a copy LocalRanks started: ends this process when its rank 0 dies, however
// it dies. Does nothing in other processes. Call first thing in main.
void EndWithParentRank();

// A TCP port on 127.0.0.1 nobody listens on now (bind to port 0, read it back).
int FreeLoopbackPort();

}  // namespace headcast
