// The model on its threads: the counts its scene asks for, the same bits for any count, the
// scheduling slices, freed memory reused.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <thread>
#include <vector>

#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/runtime/worker_pool.h"
#include "runtime/process_threads.h"

namespace liver_sim {
namespace {

std::string scene_path(const std::string& name) {
  return std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/" + name;
}

bool same_bits(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0;
}

TEST(Threads, OutOfRangeCountsAreRefusedNamingTheKey) {
  for (const char* bad : {"solver.threads=0", "solver.threads=65", "solver.threads=two"}) {
    try {
      load_scene(scene_path("aspiration_cube.yaml"), {bad});
      ADD_FAILURE() << bad << " was accepted";
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("solver.threads"), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(load_scene(scene_path("aspiration_cube.yaml"), {"solver.threads=64"}).solver.threads, 64);
  EXPECT_EQ(load_scene(scene_path("aspiration_cube.yaml")).solver.threads, 1);  // the default
  const Scene s = load_scene(scene_path("aspiration_cube.yaml"));
  LiverModel m(load_scene_mesh(s), s);
  SolverOptions o = m.solver_options();
  o.threads = 2;
  EXPECT_NE(m.set_solver_options(o).find("solver.threads"), std::string::npos);
  EXPECT_EQ(m.solver_options().threads, 1);
}

// The model starts solver.threads - 1 helpers and its loops run chunks on them. Seen to fail
// with the model's pool built on one thread whatever the scene says.
TEST(Threads, TheModelStartsAndUsesTheThreadsItsSceneAsksFor) {
  const Scene s = load_scene(scene_path("aspiration_cube.yaml"),
                             {"solver.threads=3", "solver.mode=dynamic", "solver.dt=0.001", "solver.steps=20"});
  const int before = process_threads();
  LiverModel m(load_scene_mesh(s), s);
  EXPECT_EQ(process_threads(), before + 2);
  EXPECT_EQ(m.mechanics().workers().threads(), 3);
  for (int k = 0; k < 20; ++k) ASSERT_NE(m.step().status, StepResult::Status::Diverged);
  EXPECT_GT(m.mechanics().workers().helper_chunks(), 0);
}

// The element loops at a deformed state, a velocity and damping: forces, energy and damping
// forces of 2 and 3 threads against those of one, bit for bit. Seen to fail with the gather
// adding the membranes before the tetrahedra, and with the chunks adding their element vectors
// into the forces as they finish (under a lock: the order in which threads finish).
TEST(Threads, ElementLoopsGiveTheSameBitsForAnyThreadCount) {
  struct Result {
    Eigen::VectorXd forces, damping;
    double energy;
  };
  auto evaluate = [](int threads) {
    const Scene s = load_scene(scene_path("liver_phantom.yaml"),
                               {"solver.threads=" + std::to_string(threads), "solver.mode=dynamic"});
    LiverModel m(load_scene_mesh(s), s);
    MechanicalModel& mech = m.mechanics();
    const Eigen::VectorXd& X = mech.rest_positions();
    Eigen::VectorXd x = X, v(X.size());
    for (int i = 0; i < X.size(); ++i) {  // a twist and a stretch, and a velocity field
      x[i] += 0.01 * std::sin(97.0 * X[i] + i) * X.norm() / std::sqrt(static_cast<double>(X.size()));
      v[i] = std::cos(31.0 * i);
    }
    Result r;
    mech.internal_forces(x, r.forces);
    r.energy = mech.elastic_energy(x);
    mech.snapshot_damping(x);
    mech.damping_forces(v, r.damping);
    return r;
  };
  const Result one = evaluate(1);
  for (int threads : {2, 3}) {
    const Result many = evaluate(threads);
    EXPECT_TRUE(same_bits(one.forces, many.forces)) << threads << " threads";
    EXPECT_TRUE(same_bits(one.damping, many.damping)) << threads << " threads";
    EXPECT_EQ(std::memcmp(&one.energy, &many.energy, sizeof(double)), 0) << threads << " threads";
  }
}

// Whole steps with the tube's frictional contact, suction, the capsule and damping: positions
// after every step the same bits for 1, 2 and 3 threads.
TEST(Threads, StepsGiveTheSamePositionsForAnyThreadCount) {
  auto positions = [](int threads) {
    const Scene s = load_scene(scene_path("aspiration_tube.yaml"),
                               {"solver.threads=" + std::to_string(threads), "solver.mode=dynamic",
                                "solver.dt=0.005", "solver.rayleigh_stiffness=0.02"});
    LiverModel m(load_scene_mesh(s), s);
    std::vector<Eigen::VectorXd> after;
    for (int k = 0; k < 8; ++k) {
      EXPECT_NE(m.step().status, StepResult::Status::Diverged);
      after.push_back(m.positions());
    }
    return after;
  };
  const std::vector<Eigen::VectorXd> one = positions(1);
  ASSERT_GT((one.back() - one.front()).norm(), 0);  // the tissue moves
  for (int threads : {2, 3}) {
    const std::vector<Eigen::VectorXd> many = positions(threads);
    for (size_t k = 0; k < one.size(); ++k) EXPECT_TRUE(same_bits(one[k], many[k])) << threads << " threads, step " << k;
  }
}

// Page faults of the calling thread so far (each a page the system handed over and zeroed).
long page_faults() {
  rusage usage{};
  getrusage(RUSAGE_THREAD, &usage);
  return usage.ru_minflt;
}

// Four 24 MiB blocks allocated, written and freed, as an analysis's matrices and a cloud's
// buffers are each second. By default glibc maps such a block for itself (below 32 MiB only
// once a freed one that large raised its threshold) or gives the heap's freed top back once
// it exceeds twice that threshold (at most 64 MiB, less than the 96 MiB freed here, whatever
// ran before in this process), and every round faults its pages in again (seen with
// keep_freed_memory's body removed: 72,484 of 73,728 in this test binary).
TEST(Memory, FreedBlocksAreReusedWithoutFaultingThemInAgain) {
  ASSERT_TRUE(keep_freed_memory());
  static constexpr size_t kBlock = size_t{24} << 20;
  auto round = [] {
    std::vector<std::vector<char>> blocks;
    for (char c = 1; c <= 4; ++c) blocks.emplace_back(kBlock, c);
    EXPECT_EQ(blocks[0][kBlock / 2] + blocks[3][kBlock / 3], 5);
  };
  round();  // the heap grows to hold them, once
  const long before = page_faults();
  for (int i = 0; i < 3; ++i) round();
  const long pages = static_cast<long>(4 * kBlock) / sysconf(_SC_PAGESIZE);
  EXPECT_LT(page_faults() - before, 3 * pages / 100) << "of " << 3 * pages << " pages written";
}

// The slice each thread asked for, as sched_getattr reports it (ns): for normal scheduling the
// kernel's answer in sched_runtime (Linux 6.12+; earlier kernels report 0).
uint64_t slice_of(long tid) {
  struct {
    uint32_t size, policy;
    uint64_t flags;
    int32_t nice;
    uint32_t priority;
    uint64_t runtime, deadline, period;
  } a{};
  if (syscall(SYS_sched_getattr, tid, &a, sizeof a, 0) != 0) return 0;
  return a.runtime;
}

// The message threads take the slice; the caller (the simulation thread) and a background job
// (nice +10) keep theirs, the job its nice value too. Killed by the background jobs not left out
// (tried: the job took the slice).
TEST(Threads, OtherThreadsTakeTheSliceTheCallerAndBackgroundJobsKeepTheirs) {
  std::atomic<long> helper{0}, job{0};
  std::atomic<bool> done{false};
  std::thread a([&] {
    helper = syscall(SYS_gettid);
    while (!done) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  });
  std::thread b([&] {
    lower_calling_thread_priority();
    job = syscall(SYS_gettid);
    while (!done) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  });
  while (helper == 0 || job == 0) std::this_thread::yield();
  const long self = syscall(SYS_gettid);
  const uint64_t before = slice_of(self);
  EXPECT_EQ(set_slice_of_other_threads(2e-4), "");
  if (slice_of(helper) == 0) {
    done = true;
    a.join();
    b.join();
    GTEST_SKIP() << "a kernel before 6.12: no slice per thread";
  }
  EXPECT_EQ(slice_of(helper), 200000u);
  EXPECT_NE(slice_of(job), 200000u);
  EXPECT_EQ(getpriority(PRIO_PROCESS, static_cast<id_t>(job.load())), 10);
  EXPECT_EQ(slice_of(self), before);
  EXPECT_NE(set_slice_of_other_threads(1.0), "");  // beyond the bounds
  done = true;
  a.join();
  b.join();
}

}  // namespace
}  // namespace liver_sim
