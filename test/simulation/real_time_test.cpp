// The haptic frame loop allocates no heap memory once it runs: every malloc in the process is
// counted (the test binary interposes malloc and its relatives) while frames are stepped. Found
// this way: the capped frame's status message outgrew the string's inline buffer.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <string>

#include "liver_sim/simulation/liver_model.h"

// A sanitizer brings its own malloc, which this one would bypass.
#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define LIVER_SIM_OWN_MALLOC 1
#endif
#endif
#if !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__) && !defined(LIVER_SIM_OWN_MALLOC)
#define LIVER_SIM_COUNT_MALLOC 1
namespace {
std::atomic<bool> counting{false};
std::atomic<long> allocations{0};
}  // namespace
extern "C" {
void* __libc_malloc(size_t);
void* __libc_calloc(size_t, size_t);
void* __libc_realloc(void*, size_t);
void* __libc_memalign(size_t, size_t);
void* malloc(size_t n) {
  if (counting) ++allocations;
  return __libc_malloc(n);
}
void* calloc(size_t n, size_t size) {
  if (counting) ++allocations;
  return __libc_calloc(n, size);
}
void* realloc(void* p, size_t n) {
  if (counting) ++allocations;
  return __libc_realloc(p, n);
}
int posix_memalign(void** p, size_t alignment, size_t n) {
  if (counting) ++allocations;
  *p = __libc_memalign(alignment, n);
  return *p ? 0 : 12;  // ENOMEM
}
void* aligned_alloc(size_t alignment, size_t n) {
  if (counting) ++allocations;
  return __libc_memalign(alignment, n);
}
}
#endif

namespace liver_sim {
namespace {

#ifdef LIVER_SIM_COUNT_MALLOC
// Steps frames of one modified-Newton iteration under a breathing load and checks that those
// which keep their factor allocate nothing. Frames that refresh the factor are left out: CHOLMOD
// and OpenBLAS allocate inside a numeric factorisation.
void expect_frames_allocate_nothing(const std::string& scene, const std::string& dt) {
  const Scene s = load_scene(std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/" + scene,
                             {"solver.mode=dynamic", "solver.dt=" + dt, "solver.strategy=modified_newton",
                              "solver.max_iterations=1", "solver.tolerance=1e-300"});
  LiverModel m(load_scene_mesh(s), s);
  for (int k = 1; k <= 5; ++k) ASSERT_NE(m.step().status, StepResult::Status::Diverged);  // factor, workspaces
  int counted = 0;
  for (int k = 6; k <= 30; ++k) {
    m.set_load_scale(1 + 0.5 * std::sin(2 * M_PI * k * s.solver.dt));
    allocations = 0;
    counting = true;
    const StepResult r = m.step();
    counting = false;
    ASSERT_NE(r.status, StepResult::Status::Diverged) << r.message;
    if (r.factorizations > 0) continue;
    EXPECT_EQ(allocations.load(), 0) << "frame " << k;
    ++counted;
  }
  EXPECT_GE(counted, 20);
}
#endif

TEST(RealTime, MallocIsCounted) {
#ifndef LIVER_SIM_COUNT_MALLOC
  GTEST_SKIP() << "the sanitizer owns malloc";
#else
  allocations = 0;
  counting = true;
  void* p = std::malloc(64);
  counting = false;
  std::free(p);
  EXPECT_EQ(allocations.load(), 1);
#endif
}

TEST(RealTime, HapticCubeFramesAllocateNothing) {
#ifndef LIVER_SIM_COUNT_MALLOC
  GTEST_SKIP() << "the sanitizer owns malloc";
#else
  expect_frames_allocate_nothing("aspiration_cube.yaml", "0.001");
#endif
}

TEST(RealTime, PhantomFramesWithVesselsAllocateNothing) {
#ifndef LIVER_SIM_COUNT_MALLOC
  GTEST_SKIP() << "the sanitizer owns malloc";
#else
  expect_frames_allocate_nothing("liver_phantom.yaml", "0.01");
#endif
}

}  // namespace
}  // namespace liver_sim
