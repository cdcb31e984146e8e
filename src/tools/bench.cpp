// Run time against error (doc/performance.md). The scenario: the scene's static
// equilibrium (solved once, tightly), then dynamic frames of solver.dt in which the scene's loads
// breathe, scaled by 1 + A sin(2 pi f t) (suction on the cube, gravity on the liver: the smooth
// inputs of an OR session), and the instruments of --instruments (a YAML file with an
// `instruments:` list in the scene format: a probe pressing and sweeping, a grasper lifting) move
// along their trajectories from the start of the frames (or, for a file with a `press_sweep:`
// map, a probe pressing and sweeping as the node's measurement poses it: bench_press_sweep.h).
// Each solver strategy runs it, every frame timed, and its displacement field is compared with a
// converged reference run (Newton-Krylov to a residual of 1e-10).
//   bench --scene FILE [--instruments FILE] [--set K=V]... [--frames N] [--amplitude A]
//         [--frequency F] [--strategy SPEC]... [--threads N,...] [--load N,...] [--realtime-priority P]
//         [--paced] [--node-placement] [--csv FILE] [--quiet]
// SPEC is STRATEGY[:ITERATIONS[:TOLERANCE]]: the solver.strategy, the Newton iterations allowed
// per frame (solver.max_iterations) and the residual tolerance (solver.tolerance; 0 means "always
// do ITERATIONS"). Each strategy runs once per thread count of --threads (solver.threads,
// default 1) and, for each, once per count of --load: that many threads that keep processors
// busy while the frames are timed, one per processor the process may use, in turn (a build or
// another program on the same computer; default 0). --realtime-priority runs the timed frames
// (and the model's helpers) under SCHED_FIFO, the load at normal priority. One CSV row per run on
// standard output (or --csv), progress on stderr. Pin it (taskset) for timings.
#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <atomic>
#include <climits>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "liver_sim/runtime/frame_clock.h"
#include "liver_sim/runtime/worker_pool.h"
#include "liver_sim/simulation/liver_model.h"
#include "bench_press_sweep.h"
#include "tool_io.h"

namespace {

using liver_sim::LiverModel;
using liver_sim::Scene;
using liver_sim::StepResult;

struct Spec {
  std::string text, strategy;
  int iterations = 30;
  double tolerance = 1e-6;
};

struct Run {
  std::vector<double> frame_ms;
  std::vector<Eigen::VectorXd> displacement;  // per frame
  int newton_iterations = 0, factorizations = 0, background_factorizations = 0, linear_iterations = 0, diverged = 0,
      recoveries = 0;  // recovery steps (NewtonStepper::kRecoveryAfterRollbacks)
  long contacts = 0;  // loaded contacts, summed over the frames
  double factorization_ms = 0;
  std::string first_rollback;  // why the first rolled-back frame was
  long tets = 0, dofs = 0;
};

// A --strategy SPEC, STRATEGY[:ITERATIONS[:TOLERANCE]]; throws std::invalid_argument saying
// what is wrong with it.
Spec parse_spec(const std::string& s) {
  Spec spec;
  spec.text = s;
  std::vector<std::string> parts;
  std::stringstream in(s);
  for (std::string part; std::getline(in, part, ':');) parts.push_back(part);
  if (parts.empty() || parts.size() > 3 || !liver_sim::parse_strategy(parts[0]))
    throw std::invalid_argument("'" + s + "' is not STRATEGY[:ITERATIONS[:TOLERANCE]] with a strategy of the list");
  spec.strategy = parts[0];
  char* end = nullptr;
  if (parts.size() > 1) {
    const long n = std::strtol(parts[1].c_str(), &end, 10);
    if (parts[1].empty() || *end || n < 1 || n > INT_MAX)  // solver.max_iterations bounds it further
      throw std::invalid_argument("ITERATIONS '" + parts[1] + "' is not a whole number >= 1");
    spec.iterations = static_cast<int>(n);
  }
  if (parts.size() > 2) {
    spec.tolerance = std::strtod(parts[2].c_str(), &end);
    if (parts[2].empty() || *end || !std::isfinite(spec.tolerance) || spec.tolerance < 0)
      throw std::invalid_argument("TOLERANCE '" + parts[2] + "' is not a number >= 0");
  }
  return spec;
}

struct Loading {
  int frames = 100;
  double amplitude = 0.5, frequency = 1.0;  // -, Hz
  std::vector<liver_sim::InstrumentOptions> instruments;  // added to the scene's
  int realtime_priority = 0;  // of the timed runs' threads (SCHED_FIFO), 0: normal scheduling
  bool paced = false;         // frames start on their slots of solver.dt, as the node's loop
  // The frames on the first processor this process may use, the background factorisations on
  // the others, as the node with ~cpu_affinity places them.
  bool node_placement = false;
};

// Threads that keep processors busy while frames are timed, as a compiler or another program
// would: thread i spins on the i-th processor this process may use (in turn).
class CompetingLoad {
 public:
  explicit CompetingLoad(int threads) {
    cpu_set_t allowed;
    CPU_ZERO(&allowed);
    sched_getaffinity(0, sizeof allowed, &allowed);
    std::vector<int> cpus;
    for (int c = 0; c < CPU_SETSIZE; ++c)
      if (CPU_ISSET(c, &allowed)) cpus.push_back(c);
    for (int i = 0; i < threads; ++i)
      threads_.emplace_back([this, cpu = cpus[i % cpus.size()]] {
        cpu_set_t one;
        CPU_ZERO(&one);
        CPU_SET(cpu, &one);
        pthread_setaffinity_np(pthread_self(), sizeof one, &one);
        liver_sim::set_realtime_priority(0);  // the competitor is an ordinary program
        double x = 1;
        while (!stop_.load(std::memory_order_relaxed)) x = std::sqrt(x + 1);
        sink_ = x;
      });
  }
  ~CompetingLoad() {
    stop_ = true;
    for (std::thread& t : threads_) t.join();
  }

 private:
  std::vector<std::thread> threads_;
  std::atomic<bool> stop_{false};
  std::atomic<double> sink_{0};  // keeps the busy loop's work
};

// The converged solves (the start and the reference) have no time budget (--set solver.time_budget
// is for the timed runs, as the node's one frame).
constexpr const char* kNoBudget = "solver.time_budget=1e9";

// The scene's static equilibrium, to a residual of 1e-10.
Eigen::VectorXd equilibrium(const std::string& scene_path, std::vector<std::string> overrides) {
  for (const char* o : {"solver.mode=static", "solver.strategy=newton_krylov", "solver.max_iterations=100",
                        "solver.tolerance=1e-10", kNoBudget})
    overrides.push_back(o);
  const Scene scene = liver_sim::load_scene(scene_path, overrides);
  LiverModel model(liver_sim::load_scene_mesh(scene), scene);
  const StepResult r = model.step();
  if (!r.converged()) throw std::runtime_error("the static equilibrium did not converge: " + r.message);
  return model.positions();
}

// The frames of one strategy on `threads` threads, beside `load` busy threads.
Run run(const std::string& scene_path, std::vector<std::string> overrides, const Spec& spec, const Loading& loading,
        int threads, int load, const Eigen::VectorXd& start, bool quiet) {
  const int frames = loading.frames;
  overrides.push_back("solver.threads=" + std::to_string(threads));
  overrides.push_back("solver.mode=dynamic");
  overrides.push_back("solver.strategy=" + spec.strategy);
  overrides.push_back("solver.max_iterations=" + std::to_string(spec.iterations));
  std::ostringstream tol;
  tol << std::setprecision(17) << (spec.tolerance > 0 ? spec.tolerance : 1e-300);
  overrides.push_back("solver.tolerance=" + tol.str());
  Scene scene = liver_sim::load_scene(scene_path, overrides);
  scene.instruments.insert(scene.instruments.end(), loading.instruments.begin(), loading.instruments.end());
  // The model's helper threads inherit the scheduling of the thread that builds the model.
  struct Priority {
    explicit Priority(int p) {
      const std::string refused = liver_sim::set_realtime_priority(p);
      if (!refused.empty()) throw std::runtime_error("--realtime-priority " + std::to_string(p) + ": " + refused);
    }
    ~Priority() { liver_sim::set_realtime_priority(0); }
  } priority(loading.realtime_priority);
  // Placed as the node: this thread (and the model's helpers, which inherit it) on the first
  // processor, the background on the rest; restored after the run.
  struct Placement {
    explicit Placement(bool on) : all(liver_sim::processors_of_calling_thread()) {
      if (!on) return;
      if (all.size() < 2) throw std::runtime_error("--node-placement needs two processors (taskset -c 0,1)");
      frames = {all.front()};
      background.assign(all.begin() + 1, all.end());
      const std::string refused = liver_sim::pin_calling_thread(frames);
      if (!refused.empty()) throw std::runtime_error("--node-placement: " + refused);
    }
    ~Placement() { liver_sim::pin_calling_thread(all); }
    std::vector<int> all, frames, background;
  } placement(loading.node_placement);
  LiverModel model(liver_sim::load_scene_mesh(scene), scene);
  if (!placement.background.empty()) {
    const std::string refused = model.stepper().place_background(placement.background);
    if (!refused.empty()) throw std::runtime_error("--node-placement: " + refused);
  }
  model.set_positions(start);
  Run r;
  r.tets = model.mesh().T.rows();
  r.dofs = 3 * model.mesh().V.rows();
  CompetingLoad competing(load);
  // Paced: frames on the node's grid of slots; the time a frame leaves is the background
  // thread's.
  liver_sim::FrameClock slots(scene.solver.dt, liver_sim::FrameClock::kCatchUp);
  for (int k = 0; k < frames; ++k) {
    if (loading.paced) slots.sleep();
    const double t = (k + 1) * scene.solver.dt;
    model.set_load_scale(1 + loading.amplitude * std::sin(2 * M_PI * loading.frequency * t));
    const StepResult s = model.step();
    r.frame_ms.push_back(s.timing.total_ms);
    r.displacement.push_back(model.positions() - start);
    r.newton_iterations += s.iterations;
    r.factorizations += s.factorizations;
    r.background_factorizations += s.background_factorizations;
    r.linear_iterations += s.linear_iterations;
    r.factorization_ms += s.timing.factorization_ms;
    r.contacts += s.contacts;
    if (s.status == StepResult::Status::Diverged && r.diverged++ == 0) r.first_rollback = s.message;
    r.recoveries += s.recovery;
  }
  if (!quiet)
    std::cerr << "bench: " << spec.text << ", " << threads << " threads, load " << load << ": " << r.tets
              << " tetrahedra, " << frames << " frames, "
              << r.newton_iterations << " Newton iterations, " << r.factorizations << " factorisations";
  if (!quiet && r.diverged) std::cerr << ", " << r.diverged << " frames rolled back (first: " << r.first_rollback << ")";
  if (!quiet && r.recoveries) std::cerr << ", " << r.recoveries << " recovery steps";
  if (!quiet) std::cerr << "\n";
  return r;
}

double percentile(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * v.size()))];
}

struct Options {
  std::string scene, instruments, csv;
  std::vector<std::string> overrides;
  std::vector<Spec> specs;
  Loading loading;  // its instruments read from `instruments` once the command line is taken
  std::vector<int> thread_counts{1}, loads{0};
  bool quiet = false;
};

// The command line into `o`: the exit status when the tool is to stop, else nothing.
std::optional<int> parse_args(int argc, char** argv, Options* o) {
  namespace tool = liver_sim::tool;
  CLI::App app(
      "Times dynamic frames of solver.dt from the scene's static equilibrium, the scene's loads scaled\n"
      "by 1 + A sin(2 pi f t), for each solver strategy, against a converged reference run.",
      "bench");
  tool::describe(app,
                 "usage: bench --scene FILE [--instruments FILE] [--set K=V]... [--frames N] [--amplitude A]\n"
                 "             [--frequency HZ] [--strategy STRATEGY[:ITERATIONS[:TOLERANCE]]]... [--threads N,...]\n"
                 "             [--load N,...] [--realtime-priority P] [--paced] [--node-placement]\n"
                 "             [--csv FILE] [--quiet]\n");
  app.add_option("--scene", o->scene, "YAML scene (README, 'Scene format'); required")->option_text("FILE")->required();
  app.add_option("--instruments", o->instruments,
                 "YAML file with an instruments: list in the scene format, moving along\n"
                 "their trajectories from the first frame (e.g. config/bench/*.yaml), or with\n"
                 "a press_sweep: map, a probe pressing into the surface found under it")
      ->option_text("FILE");
  tool::add_overrides(app, o->overrides,
                      "override a scalar of the scene, e.g. --set solver.dt=0.001 (repeatable)");
  app.add_option("--frames", o->loading.frames, "timed frames per run, >= 1 (default 100)")
      ->option_text("N")
      ->check(tool::at_least(1));
  app.add_option("--amplitude", o->loading.amplitude, "relative amplitude of the breathing loads (default 0.5)")
      ->option_text("A")
      ->check(tool::any_number());
  app.add_option("--frequency", o->loading.frequency, "their frequency (Hz, default 1)")
      ->option_text("HZ")
      ->check(tool::any_number());
  app.add_option("--strategy",
                 "a run (repeatable, at least one): STRATEGY is one of newton_krylov,\n"
                 "full_newton, full_newton_eigen, reused_factor_cg, cg, modified_newton;\n"
                 "ITERATIONS the Newton iterations per frame (default 30); TOLERANCE the\n"
                 "residual tolerance (default 1e-6; 0: always ITERATIONS)")
      ->option_text("SPEC")
      ->required()
      ->take_all()
      ->allow_extra_args(false)
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            try {
              parse_spec(text);
              return "";
            } catch (const std::invalid_argument& e) {
              return e.what();
            }
          },
          "SPEC"))
      ->each([o](const std::string& text) { o->specs.push_back(parse_spec(text)); });
  tool::add_list(app, "--threads", "N,...", o->thread_counts,
                 "solver.threads of the runs, each " + tool::thread_bounds() + " (default 1)")
      ->check(tool::thread_count());
  tool::add_list(app, "--load", "N,...", o->loads,
                 "busy threads beside the runs, one run per count, each >= 0 (default 0)")
      ->check(tool::at_least(0));
  app.add_option("--realtime-priority", o->loading.realtime_priority,
                 "SCHED_FIFO priority (1-99) of the timed runs' threads (default 0: normal)")
      ->option_text("P")
      ->check(tool::integer("in [0, 99]", [](long p) { return p >= 0 && p <= 99; }));
  app.add_flag("--paced", o->loading.paced,
               "each frame starts on its slot of solver.dt of wall time, a late one at once,\n"
               "as in the node (default: back to back); for solver.background_refresh");
  app.add_flag("--node-placement", o->loading.node_placement,
               "the frames on the first processor this process may use, the background\n"
               "factorisations on the others, as the node with ~cpu_affinity (run it under\n"
               "taskset -c 0,1)");
  app.add_option("--csv", o->csv, "write the CSV rows (one per run) to FILE instead of standard output")
      ->option_text("FILE");
  app.add_flag("--quiet", o->quiet, "no progress on standard error");
  return tool::parse(app, argc, argv);
}

int run_all(const Options& o) {
  Loading loading = o.loading;
  namespace bench = liver_sim::bench;
  const std::optional<bench::PressSweep> press =
      o.instruments.empty() ? std::nullopt : bench::read_press_sweep(o.instruments);
  if (!o.instruments.empty() && !press) loading.instruments = liver_sim::load_instruments(o.instruments);
  const int frames = loading.frames;
  Spec reference_spec = parse_spec("newton_krylov:50:1e-10");
  reference_spec.text = "reference";
  const Eigen::VectorXd start = equilibrium(o.scene, o.overrides);
  if (press) {
    const Scene scene = liver_sim::load_scene(o.scene, o.overrides);
    double surface;
    try {
      surface = bench::surface_height(liver_sim::load_scene_mesh(scene).T, start, press->above);
    } catch (const std::runtime_error& e) {
      throw std::runtime_error(o.instruments + ": press_sweep.above: " + e.what());
    }
    loading.instruments = {bench::press_sweep_instrument(*press, surface)};
    if (!o.quiet) std::cerr << "bench: press_sweep: the surface lies at z = " << surface << " m under the probe\n";
  }
  std::vector<std::string> reference_overrides = o.overrides;
  reference_overrides.push_back(kNoBudget);
  const Run reference = run(o.scene, reference_overrides, reference_spec, loading, o.thread_counts[0], 0, start, o.quiet);
  double peak = 0;  // errors are relative to the largest motion from the equilibrium in the reference run
  for (const Eigen::VectorXd& u : reference.displacement) peak = std::max(peak, u.cwiseAbs().maxCoeff());

  std::ofstream file;
  if (!o.csv.empty()) file.open(o.csv);
  std::ostream& out = o.csv.empty() ? std::cout : file;
  out << "scene,tetrahedra,dofs,strategy,iterations,tolerance,threads,load,frames,median_ms,mean_ms,p95_ms,fps,"
         "max_error,final_error,newton_iterations,linear_iterations,factorizations,factorization_ms,diverged,contacts,"
         "background_factorizations,recoveries\n"
      << std::setprecision(6);
  for (const Spec& spec : o.specs)
    for (int threads : o.thread_counts)
      for (int load : o.loads) {
        const Run r = run(o.scene, o.overrides, spec, loading, threads, load, start, o.quiet);
        double max_error = 0;
        for (int k = 0; k < frames; ++k)
          max_error = std::max(max_error, (r.displacement[k] - reference.displacement[k]).cwiseAbs().maxCoeff());
        const double final_error = (r.displacement.back() - reference.displacement.back()).cwiseAbs().maxCoeff();
        double mean = 0;
        for (double t : r.frame_ms) mean += t / frames;
        out << o.scene << ',' << r.tets << ',' << r.dofs << ',' << spec.strategy << ',' << spec.iterations << ','
            << spec.tolerance << ',' << threads << ',' << load << ',' << frames << ',' << percentile(r.frame_ms, 0.5)
            << ',' << mean << ',' << percentile(r.frame_ms, 0.95) << ',' << 1000.0 / mean << ',' << max_error / peak
            << ',' << final_error / peak << ',' << r.newton_iterations << ',' << r.linear_iterations << ','
            << r.factorizations << ',' << (r.factorizations ? r.factorization_ms / r.factorizations : 0.0) << ','
            << r.diverged << ',' << static_cast<double>(r.contacts) / frames << ',' << r.background_factorizations
            << ',' << r.recoveries << '\n' << std::flush;
      }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  if (const std::optional<int> status = parse_args(argc, argv, &opt)) return *status;
  try {
    return run_all(opt);
  } catch (const std::exception& e) {
    std::cerr << "bench: " << e.what() << "\n";
    return 1;
  }
}
