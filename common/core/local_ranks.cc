#include "common/core/local_ranks.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

#include "common/core/log.h"

extern char** environ;

namespace headcast {

namespace {
constexpr const char* kParentRankEnv = "HEADCAST_PARENT_RANK_PID";
}  // namespace

void EndWithParentRank() {
  const char* parent = std::getenv(kParentRankEnv);
  if (!parent) return;
  // Killed rank 0 (kill -9, OOM) would otherwise leave this copy in an
  // all-reduce until Gloo's 300 s timeout.
  prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (getppid() != static_cast<pid_t>(std::atoll(parent))) _exit(1);  // it died before prctl
}

int FreeLoopbackPort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) throw std::runtime_error(std::string("socket: ") + std::strerror(errno));
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  socklen_t len = sizeof(a);
  const bool ok = bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0 &&
                  getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0;
  const int error = errno;
  close(fd);
  if (!ok) throw std::runtime_error(std::string("no free loopback port: ") + std::strerror(error));
  return ntohs(a.sin_port);
}

LocalRanks::LocalRanks(int processes, const std::vector<std::string>& args) {
  if (processes < 2 || processes > 64) throw std::invalid_argument("--processes must be 2..64 to start copies");
  port_ = FreeLoopbackPort();
  // One thread for OpenMP and OpenBLAS from the start (their pools are made when the libraries load).
  std::vector<std::string> env_strings = {"OMP_NUM_THREADS=1", "OPENBLAS_NUM_THREADS=1",
                                          std::string(kParentRankEnv) + "=" + std::to_string(getpid())};
  for (char** e = environ; *e; ++e)
    if (std::strncmp(*e, "OMP_NUM_THREADS=", 16) != 0 && std::strncmp(*e, "OPENBLAS_NUM_THREADS=", 21) != 0 &&
        std::strncmp(*e, kParentRankEnv, std::strlen(kParentRankEnv)) != 0)
      env_strings.emplace_back(*e);
  std::vector<char*> env;
  for (std::string& e : env_strings) env.push_back(e.data());
  env.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
  for (int rank = 1; rank < processes; ++rank) {
    std::vector<std::string> a = {"/proc/self/exe"};
    a.insert(a.end(), args.begin(), args.end());
    for (const std::string& s :
         {std::string("--processes"), std::string("1"), std::string("--threads"), std::string("1"),
          std::string("--rank"), std::to_string(rank), std::string("--world-size"), std::to_string(processes),
          std::string("--master-addr"), std::string("127.0.0.1"), std::string("--master-port"), std::to_string(port_)})
      a.push_back(s);
    std::vector<char*> argv;
    for (std::string& s : a) argv.push_back(s.data());
    argv.push_back(nullptr);
    pid_t pid = 0;
    const int rc = posix_spawn(&pid, "/proc/self/exe", &actions, nullptr, argv.data(), env.data());
    if (rc != 0) {
      posix_spawn_file_actions_destroy(&actions);
      stopping_ = true;
      for (pid_t p : children_) kill(p, SIGTERM);
      for (pid_t p : children_) waitpid(p, nullptr, 0);
      throw std::runtime_error("cannot start data-parallel rank " + std::to_string(rank) + ": " + std::strerror(rc));
    }
    children_.push_back(pid);
  }
  posix_spawn_file_actions_destroy(&actions);
  watcher_ = std::thread([this] { Watch(); });
}

// A copy that fails leaves rank 0 waiting in an all-reduce until Gloo's
// timeout; stopping at once is better: the checkpoints on disk are intact.
void LocalRanks::Watch() {
  for (size_t reaped = 0; reaped < children_.size(); ++reaped) {
    int status = 0;
    pid_t pid;
    do {
      pid = waitpid(-1, &status, 0);
    } while (pid < 0 && errno == EINTR);
    if (pid < 0) return;
    int rank = 0;
    for (size_t k = 0; k < children_.size(); ++k)
      if (children_[k] == pid) rank = static_cast<int>(k) + 1;
    if (rank == 0) {  // not one of ours (another child of this process)
      --reaped;
      continue;
    }
    const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    if (ok || stopping_) continue;
    failed_.push_back(rank);
    spdlog::error("data-parallel rank {} of {} failed ({} {}); stopping", rank, children_.size() + 1,
                  WIFEXITED(status) ? "exit status" : "signal",
                  WIFEXITED(status) ? WEXITSTATUS(status) : WTERMSIG(status));
    for (pid_t p : children_) kill(p, SIGTERM);
    std::_Exit(1);
  }
}

void LocalRanks::Wait() {
  if (watcher_.joinable()) watcher_.join();
  if (!failed_.empty()) throw std::runtime_error("data-parallel rank " + std::to_string(failed_.front()) + " failed");
}

LocalRanks::~LocalRanks() {
  if (!watcher_.joinable()) return;
  stopping_ = true;
  for (pid_t p : children_) kill(p, SIGTERM);
  watcher_.join();
}

}  // namespace headcast
