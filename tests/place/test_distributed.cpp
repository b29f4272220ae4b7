// Data-parallel training over libtorch's c10d (Gloo over a TCPStore on 127.0.0.1). Rank 1 runs in a
// child process (this test binary re-run on the disabled test below), so a rank can really die.
#include <arpa/inet.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <thread>
#include <vector>

#include "stillpoint/common/error.hpp"
#include "stillpoint/place/distributed.hpp"
#include "stillpoint/place/model.hpp"
#include "stillpoint/place/trainer.hpp"
#include "tiny_places.hpp"

extern char** environ;

namespace sp::place {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// A port nobody listens on now (the kernel's pick for port 0).
int free_port() {
  const int s = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  socklen_t len = sizeof(a);
  if (bind(s, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0 ||
      getsockname(s, reinterpret_cast<sockaddr*>(&a), &len) != 0) {
    close(s);
    return 29517;
  }
  close(s);
  return ntohs(a.sin_port);
}

// Two places folders of 12 random 80×60 views each, 0.2 m apart along x: neighbours are positives,
// the other room's views negatives. Written once, atomically: ranks and parallel tests read it.
fs::path make_places() {
  const fs::path root = fs::path(SP_TEST_TMP_DIR) / "place_ddp" / "data";
  if (fs::exists(root)) return root;
  const fs::path tmp = root.string() + ".tmp" + std::to_string(getpid());
  for (int room = 0; room < 2; ++room) {
    const fs::path dir = tmp / (room == 0 ? "room_a" : "room_b");
    fs::create_directories(dir / "rgb");
    std::ofstream poses(dir / "poses.txt");
    std::ofstream(dir / "scene.txt") << (room == 0 ? "a" : "b") << "\n";
    for (int i = 0; i < 12; ++i) {
      cv::Mat im(60, 80, CV_8UC3);
      cv::RNG rng(static_cast<uint64_t>(100 * room + i + 1));
      rng.fill(im, cv::RNG::UNIFORM, 0, 256);
      const std::string name = cv::format("rgb/%06d.jpg", i);
      cv::imwrite((dir / name).string(), im);
      poses << name << " " << 0.2 * i << " 0 0 0 0 0 1\n";
    }
  }
  std::error_code ec;
  fs::rename(tmp, root, ec);  // fails harmlessly when another process got there first
  if (ec) fs::remove_all(tmp);
  return root;
}

TrainOptions tiny_options(const fs::path& out) {
  TrainOptions o;
  o.data = {make_places()};
  o.out = out;
  o.model = ModelConfig::scaled(ModelConfig::small(), 1.0 / 3.0, 1.0);  // widths 8-16-32-64
  o.model.clusters = 8;
  o.model.input_height = 64;
  o.model.input_width = 96;
  o.epochs = 2;
  // SGD, not Adam: Adam divides by √v, which blows float-rounding noise in near-zero gradients up to
  // full-size steps, so "same weights to 1e-5" would test rounding, not the all-reduce.
  o.optimizer = "sgd";
  o.lr = 0.01;
  o.negatives = 2;
  o.negative_pool = 8;
  o.queries_per_epoch = 8;
  o.batch = 4;
  o.refresh_every = 4;  // refresh before every step: exercises the sharded cache too
  o.kmeans_images = 12;
  o.seed = 3;
  o.threads = 1;
  o.progress = false;
  o.dist.master_port = free_port();
  o.dist.timeout_s = 3;
  return o;
}

// Runs rank 1 in a child process: this binary on the disabled test below, options via the environment.
pid_t spawn_rank1(const TrainOptions& o, const fs::path& out) {
  std::vector<std::string> env;
  for (char** e = environ; *e; ++e) env.emplace_back(*e);
  env.push_back("SP_DDP_PORT=" + std::to_string(o.dist.master_port));
  env.push_back("SP_DDP_OUT=" + out.string());
  env.push_back("SP_DDP_EPOCHS=" + std::to_string(o.epochs));
  env.push_back("SP_DDP_BATCH=" + std::to_string(o.batch));
  env.push_back("SP_DDP_QUERIES=" + std::to_string(o.queries_per_epoch));
  env.push_back("SP_DDP_LR=" + fmt::format("{:.17g}", o.lr));  // exact: --lr is compared over ranks
  env.push_back("SP_DDP_PATIENCE=" + std::to_string(o.patience));
  if (!o.val.empty()) env.push_back("SP_DDP_VAL=" + o.val.front().string());
  std::vector<char*> envp;
  for (auto& e : env) envp.push_back(e.data());
  envp.push_back(nullptr);
  const std::string exe = fs::read_symlink("/proc/self/exe").string();
  std::string a0 = exe, a1 = "--gtest_also_run_disabled_tests",
              a2 = "--gtest_filter=PlaceDistributed.DISABLED_Rank1Child";
  char* argv[] = {a0.data(), a1.data(), a2.data(), nullptr};
  pid_t pid = 0;
  if (posix_spawn(&pid, exe.c_str(), nullptr, nullptr, argv, envp.data()) != 0) return -1;
  return pid;
}

int wait_exit_code(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

struct WeightDiff {
  double global = 0;      // ‖a − b‖ / ‖b‖ over all parameters concatenated
  double per_tensor = 0;  // largest max|a − b| / (max|b| + 1e-4) of one tensor
  std::string where;      // that tensor
};

// How far apart two model files' weights are. Per tensor, not per element: single weights near 0
// would make float rounding (the batch summed in another order) look like a large relative error; the
// 1e-4 judges tensors still at ~0 (LayerNorm biases moved by 1e-7) absolutely.
WeightDiff weight_diff(const fs::path& a, const fs::path& b) {
  auto ma = load_model(a), mb = load_model(b);
  const auto pa = ma->named_parameters(), pb = mb->named_parameters();
  WeightDiff d;
  double num = 0, den = 0;
  for (const auto& item : pb) {
    const auto delta = pa[item.key()] - item.value();
    num += delta.pow(2).sum().item<double>();
    den += item.value().pow(2).sum().item<double>();
    const double rel = delta.abs().max().item<double>() / (item.value().abs().max().item<double>() + 1e-4);
    if (rel > d.per_tensor) d.per_tensor = rel, d.where = item.key();
  }
  d.global = std::sqrt(num / den);
  return d;
}

// Rank 1 of the tests below; only runs when a test spawned it.
TEST(PlaceDistributed, DISABLED_Rank1Child) {
  const char* port = std::getenv("SP_DDP_PORT");
  if (!port) GTEST_SKIP() << "started by the other PlaceDistributed tests";
  TrainOptions o = tiny_options(std::getenv("SP_DDP_OUT"));
  o.dist.master_port = std::atoi(port);
  o.epochs = std::atoi(std::getenv("SP_DDP_EPOCHS"));
  o.batch = std::atoi(std::getenv("SP_DDP_BATCH"));
  o.queries_per_epoch = std::atoi(std::getenv("SP_DDP_QUERIES"));
  o.lr = std::atof(std::getenv("SP_DDP_LR"));
  o.patience = std::atoi(std::getenv("SP_DDP_PATIENCE"));
  if (const char* val = std::getenv("SP_DDP_VAL")) o.val = {val};
  o.dist.world_size = 2;
  o.dist.rank = 1;
  // An exception fails this process, which the parent sees in the exit code.
  for (const auto& s : train_model(o)) EXPECT_EQ(s.rank_drift, 0.0) << "epoch " << s.epoch;
}

TEST(PlaceDistributed, TwoRanksMatchOneRankWithTheConcatenatedBatch) {
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place_ddp";
  fs::create_directories(dir);
  // Reference: one rank, 4 queries per step, 2 epochs × 2 steps.
  TrainOptions one = tiny_options(dir / "one.pt");
  const auto s1 = train_model(one);
  // Same total batch split over two ranks: 2 queries each per step.
  TrainOptions two = tiny_options(dir / "two.pt");
  two.batch = 2;
  two.dist.world_size = 2;
  two.dist.rank = 0;
  const fs::path child_out = dir / "two_rank1.pt";
  fs::remove(child_out);
  const pid_t child = spawn_rank1(two, child_out);
  ASSERT_GT(child, 0);
  const auto s2 = train_model(two);
  EXPECT_EQ(wait_exit_code(child), 0);
  EXPECT_FALSE(fs::exists(child_out)) << "only rank 0 writes the model";
  // Control: rank 0's half of each step alone must differ, or the comparison proves nothing.
  TrainOptions half = tiny_options(dir / "half.pt");
  half.batch = 2;
  half.queries_per_epoch = 4;
  train_model(half);

  ASSERT_EQ(s1.size(), 2u);
  ASSERT_EQ(s2.size(), 2u);
  for (size_t e = 0; e < s1.size(); ++e) {
    EXPECT_NEAR(s2[e].loss, s1[e].loss, 1e-5 * (1 + s1[e].loss)) << "epoch " << e + 1;
    EXPECT_NEAR(s2[e].active, s1[e].active, 1e-9) << "epoch " << e + 1;
  }
  EXPECT_GT(s1.back().loss, 0.0);
  const auto same = weight_diff(dir / "two.pt", dir / "one.pt");
  const auto control = weight_diff(dir / "half.pt", dir / "one.pt");
  std::printf("two ranks vs one: %.3g overall, %.3g in %s; rank 0's half alone vs one: %.3g, %.3g in %s\n",
              same.global, same.per_tensor, same.where.c_str(), control.global, control.per_tensor,
              control.where.c_str());
  EXPECT_LT(same.global, 1e-5);
  EXPECT_LT(same.per_tensor, 1e-4) << same.where;
  EXPECT_GT(control.global, 1e-4);
}

// Validation and early stopping over two ranks: both must stop after the same epoch (a rank that went
// on alone would wait in a collective and fail after the 3 s timeout, so its exit code tells), and
// rank 0 must report the same recall a single process computes.
TEST(PlaceDistributed, TwoRanksStopEarlyTogether) {
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place_ddp";
  fs::create_directories(dir);
  const fs::path val = test::write_tiny_places(dir / "val", {"v1", "v2"});
  TrainOptions o = tiny_options(dir / "early.pt");
  o.lr = 0;  // the val recall cannot improve: stop after 1 + patience epochs
  o.epochs = 50;
  o.patience = 2;
  o.val = {val};
  TrainOptions alone = o;
  alone.out = dir / "early_alone.pt";
  alone.dist.master_port = free_port();
  const auto s1 = train_model(alone);
  o.batch = 2;
  o.dist.world_size = 2;
  const pid_t child = spawn_rank1(o, dir / "early_rank1.pt");
  ASSERT_GT(child, 0);
  const auto s2 = train_model(o);
  EXPECT_EQ(wait_exit_code(child), 0) << "rank 1 did not stop with rank 0";
  ASSERT_EQ(s2.size(), 3u);
  ASSERT_EQ(s1.size(), 3u);
  for (size_t e = 0; e < s2.size(); ++e) {
    ASSERT_TRUE(s2[e].val.has_value());
    EXPECT_EQ(s2[e].val->recall[0], s1[e].val->recall[0]) << "epoch " << e + 1;
    EXPECT_EQ(s2[e].val->queries, s1[e].val->queries);
  }
}

// Runs rank 0 in a thread, waits for its first checkpoint, does `act` to rank 1, and returns rank 0's
// error message and how long after `act` it came. Fails (and ends the process) if rank 0 hangs.
std::pair<std::string, double> rank0_after(const char* name, int signal_to_rank1) {
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place_ddp";
  fs::create_directories(dir);
  TrainOptions o = tiny_options(dir / (std::string(name) + ".pt"));
  o.epochs = 1000;  // never finishes by itself
  o.dist.world_size = 2;
  o.dist.rank = 0;
  const fs::path ckpt_epoch = o.out.string() + ".ckpt.epoch";
  fs::remove(ckpt_epoch);
  const pid_t child = spawn_rank1(o, dir / (std::string(name) + "_rank1.pt"));
  EXPECT_GT(child, 0);
  auto rank0 = std::async(std::launch::async, [o]() -> std::string {
    try {
      train_model(o);
    } catch (const sp::Error& e) {
      return e.what();
    }
    return "no error";
  });
  const auto t0 = Clock::now();
  while (!fs::exists(ckpt_epoch) && Clock::now() - t0 < std::chrono::seconds(60))
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_TRUE(fs::exists(ckpt_epoch)) << "rank 0 never finished epoch 1";
  const auto t_signal = Clock::now();
  kill(child, signal_to_rank1);
  // Bounded: timeout 3 s plus slack; a hang here would otherwise block the whole test run.
  if (rank0.wait_for(std::chrono::seconds(20)) != std::future_status::ready) {
    ADD_FAILURE() << "rank 0 still running 20 s after rank 1 was signalled";
    kill(child, SIGKILL);
    std::_Exit(1);
  }
  const double seconds = std::chrono::duration<double>(Clock::now() - t_signal).count();
  kill(child, SIGKILL);
  wait_exit_code(child);
  return {rank0.get(), seconds};
}

TEST(PlaceDistributed, KilledRankFailsTheOtherWithAClearError) {
  const auto [msg, seconds] = rank0_after("killed", SIGKILL);
  EXPECT_NE(msg.find("lost a rank"), std::string::npos) << msg;
  EXPECT_LT(seconds, 8.0) << msg;
}

TEST(PlaceDistributed, StalledRankFailsTheOtherAfterTheTimeout) {
  const auto [msg, seconds] = rank0_after("stalled", SIGSTOP);  // alive, sockets open, silent
  EXPECT_NE(msg.find("lost a rank"), std::string::npos) << msg;
  EXPECT_LT(seconds, 10.0) << msg;
}

TEST(PlaceDistributed, RankThatNeverJoinsFailsTheRendezvous) {
  TrainOptions o = tiny_options(fs::path(SP_TEST_TMP_DIR) / "place_ddp" / "alone.pt");
  o.dist.world_size = 2;
  o.dist.timeout_s = 1;
  const auto t0 = Clock::now();
  try {
    train_model(o);
    ADD_FAILURE() << "rank 0 trained without rank 1";
  } catch (const sp::Error& e) {
    EXPECT_NE(std::string(e.what()).find("rendezvous"), std::string::npos) << e.what();
  }
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - t0).count(), 6.0);
}

TEST(PlaceDistributed, RanksWithDifferentOptionsRefuseToTrain) {
  TrainOptions o = tiny_options(fs::path(SP_TEST_TMP_DIR) / "place_ddp" / "mismatch.pt");
  o.dist.world_size = 2;
  TrainOptions other = o;
  other.queries_per_epoch = 16;
  const pid_t child = spawn_rank1(other, fs::path(SP_TEST_TMP_DIR) / "place_ddp" / "mismatch_rank1.pt");
  ASSERT_GT(child, 0);
  try {
    train_model(o);
    ADD_FAILURE() << "trained with mismatched ranks";
  } catch (const sp::Error& e) {
    EXPECT_NE(std::string(e.what()).find("disagree on --queries-per-epoch"), std::string::npos) << e.what();
  }
  EXPECT_NE(wait_exit_code(child), 0);
}

TEST(PlaceDistributed, ValidatesRankWorldSizeAndPort) {
  DistOptions d;
  d.world_size = 2;
  d.rank = 2;
  EXPECT_THROW(validate(d), sp::Error);
  d.rank = -1;
  EXPECT_THROW(validate(d), sp::Error);
  d.rank = 1;
  d.master_port = 0;
  EXPECT_THROW(validate(d), sp::Error);
  d.master_port = 29500;
  EXPECT_NO_THROW(validate(d));
  d.world_size = 0;
  d.rank = 0;
  EXPECT_THROW(validate(d), sp::Error);
  // A single process needs no master at all.
  DistOptions single;
  single.master_addr.clear();
  EXPECT_NO_THROW(validate(single));
}

}  // namespace
}  // namespace sp::place
