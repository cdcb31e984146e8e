// Run time against error (doc/performance.md). The scenario: the scene's static
// equilibrium (solved once, tightly), then dynamic frames of solver.dt in which the scene's loads
// breathe, scaled by 1 + A sin(2 pi f t) (suction on the cube, gravity on the liver: the smooth
// inputs of an OR session), and the instruments of --instruments (a YAML file with an
// `instruments:` list in the scene format: a probe pressing and sweeping, a grasper lifting) move
// along their trajectories from the start of the frames. Each solver strategy runs it, every frame
// timed, and its displacement field is compared with a converged reference run (Newton-Krylov to
// a residual of 1e-10).
//   bench --scene FILE [--instruments FILE] [--set K=V]... [--frames N] [--amplitude A]
//         [--frequency F] [--strategy SPEC]... [--threads N,...] [--load N,...] [--realtime-priority P]
//         [--paced] [--csv FILE] [--quiet]
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
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "liver_sim/runtime/frame_clock.h"
#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/runtime/worker_pool.h"

namespace {

using liver_sim::LiverModel;
using liver_sim::Scene;
using liver_sim::StepResult;

const char* kUsage =
    "usage: bench --scene FILE [--instruments FILE] [--set K=V]... [--frames N] [--amplitude A]\n"
    "             [--frequency HZ] [--strategy STRATEGY[:ITERATIONS[:TOLERANCE]]]... [--threads N,...]\n"
    "             [--load N,...] [--realtime-priority P] [--paced] [--csv FILE] [--quiet]\n"
    "Times dynamic frames of solver.dt from the scene's static equilibrium, the scene's loads scaled\n"
    "by 1 + A sin(2 pi f t), for each solver strategy, against a converged reference run.\n"
    "  --scene FILE          YAML scene (README, 'Scene format'); required\n"
    "  --instruments FILE    YAML file with an instruments: list in the scene format, moving along\n"
    "                        their trajectories from the first frame (e.g. config/bench/*.yaml)\n"
    "  --set K=V             override a scalar of the scene, e.g. --set solver.dt=0.001 (repeatable)\n"
    "  --frames N            timed frames per run, >= 1 (default 100)\n"
    "  --amplitude A         relative amplitude of the breathing loads (default 0.5)\n"
    "  --frequency HZ        their frequency (Hz, default 1)\n"
    "  --strategy SPEC       a run (repeatable, at least one): STRATEGY is one of newton_krylov,\n"
    "                        full_newton, full_newton_eigen, reused_factor_cg, cg, modified_newton;\n"
    "                        ITERATIONS the Newton iterations per frame (default 30); TOLERANCE the\n"
    "                        residual tolerance (default 1e-6; 0: always ITERATIONS)\n"
    "  --threads N,...       solver.threads of the runs, each in [1, 64] (default 1)\n"
    "  --load N,...          busy threads beside the runs, one run per count (default 0)\n"
    "  --realtime-priority P SCHED_FIFO priority (1-99) of the timed runs' threads (default 0: normal)\n"
    "  --paced               each frame starts on its slot of solver.dt of wall time, a late one at once,\n"
    "                        as in the node (default: back to back); for solver.background_refresh\n"
    "  --csv FILE            write the CSV rows (one per run) to FILE instead of standard output\n"
    "  --quiet               no progress on standard error\n"
    "  --help                this text\n";

struct Spec {
  std::string text, strategy;
  int iterations = 30;
  double tolerance = 1e-6;
};

struct Run {
  std::vector<double> frame_ms;
  std::vector<Eigen::VectorXd> displacement;  // per frame
  int newton_iterations = 0, factorizations = 0, background_factorizations = 0, linear_iterations = 0, diverged = 0;
  long contacts = 0;  // loaded contacts, summed over the frames
  double factorization_ms = 0;
  std::string first_rollback;  // why the first rolled-back frame was
  long tets = 0, dofs = 0;
};

Spec parse_spec(const std::string& s) {
  Spec spec;
  spec.text = s;
  std::stringstream in(s);
  std::string part;
  std::getline(in, spec.strategy, ':');
  if (std::getline(in, part, ':')) spec.iterations = std::stoi(part);
  if (std::getline(in, part, ':')) spec.tolerance = std::stod(part);
  return spec;
}

struct Loading {
  int frames = 100;
  double amplitude = 0.5, frequency = 1.0;  // -, Hz
  std::vector<liver_sim::InstrumentOptions> instruments;  // added to the scene's
  int realtime_priority = 0;  // of the timed runs' threads (SCHED_FIFO), 0: normal scheduling
  bool paced = false;         // frames start on their slots of solver.dt, as the node's loop
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

std::vector<int> parse_counts(const std::string& s) {
  std::vector<int> counts;
  std::stringstream in(s);
  std::string part;
  while (std::getline(in, part, ',')) {
    size_t used = 0;
    const int n = std::stoi(part, &used);
    if (used != part.size() || n < 0) throw std::invalid_argument("expected counts >= 0 separated by commas: " + s);
    counts.push_back(n);
  }
  if (counts.empty()) throw std::invalid_argument("expected counts >= 0 separated by commas: " + s);
  return counts;
}

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
  LiverModel model(liver_sim::load_scene_mesh(scene), scene);
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
  }
  if (!quiet)
    std::cerr << "bench: " << spec.text << ", " << threads << " threads, load " << load << ": " << r.tets
              << " tetrahedra, " << frames << " frames, "
              << r.newton_iterations << " Newton iterations, " << r.factorizations << " factorisations";
  if (!quiet && r.diverged) std::cerr << ", " << r.diverged << " frames rolled back (first: " << r.first_rollback << ")";
  if (!quiet) std::cerr << "\n";
  return r;
}

double percentile(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * v.size()))];
}

int main_checked(int argc, char** argv) {
  std::string scene, csv;
  std::vector<std::string> overrides;
  std::vector<Spec> specs;
  Loading loading;
  std::vector<int> thread_counts = {1}, loads = {0};
  bool quiet = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--scene" && has_value) scene = argv[++i];
    else if (a == "--set" && has_value) overrides.push_back(argv[++i]);
    else if (a == "--instruments" && has_value) loading.instruments = liver_sim::load_instruments(argv[++i]);
    else if (a == "--frames" && has_value) loading.frames = std::stoi(argv[++i]);
    else if (a == "--amplitude" && has_value) loading.amplitude = std::stod(argv[++i]);
    else if (a == "--frequency" && has_value) loading.frequency = std::stod(argv[++i]);
    else if (a == "--strategy" && has_value) specs.push_back(parse_spec(argv[++i]));
    else if (a == "--threads" && has_value) thread_counts = parse_counts(argv[++i]);
    else if (a == "--load" && has_value) loads = parse_counts(argv[++i]);
    else if (a == "--realtime-priority" && has_value) loading.realtime_priority = std::stoi(argv[++i]);
    else if (a == "--paced") loading.paced = true;
    else if (a == "--csv" && has_value) csv = argv[++i];
    else if (a == "--quiet") quiet = true;
    else {
      std::cerr << kUsage;
      return 2;
    }
  }
  const int frames = loading.frames;
  if (scene.empty() || specs.empty() || frames < 1) {
    std::cerr << kUsage;
    return 2;
  }
  Spec reference_spec = parse_spec("newton_krylov:50:1e-10");
  reference_spec.text = "reference";
  const Eigen::VectorXd start = equilibrium(scene, overrides);
  std::vector<std::string> reference_overrides = overrides;
  reference_overrides.push_back(kNoBudget);
  const Run reference = run(scene, reference_overrides, reference_spec, loading, thread_counts[0], 0, start, quiet);
  double peak = 0;  // errors are relative to the largest motion from the equilibrium in the reference run
  for (const Eigen::VectorXd& u : reference.displacement) peak = std::max(peak, u.cwiseAbs().maxCoeff());

  std::ofstream file;
  if (!csv.empty()) file.open(csv);
  std::ostream& out = csv.empty() ? std::cout : file;
  out << "scene,tetrahedra,dofs,strategy,iterations,tolerance,threads,load,frames,median_ms,mean_ms,p95_ms,fps,"
         "max_error,final_error,newton_iterations,linear_iterations,factorizations,factorization_ms,diverged,contacts,"
         "background_factorizations\n"
      << std::setprecision(6);
  for (const Spec& spec : specs)
    for (int threads : thread_counts)
      for (int load : loads) {
        const Run r = run(scene, overrides, spec, loading, threads, load, start, quiet);
        double max_error = 0;
        for (int k = 0; k < frames; ++k)
          max_error = std::max(max_error, (r.displacement[k] - reference.displacement[k]).cwiseAbs().maxCoeff());
        const double final_error = (r.displacement.back() - reference.displacement.back()).cwiseAbs().maxCoeff();
        double mean = 0;
        for (double t : r.frame_ms) mean += t / frames;
        out << scene << ',' << r.tets << ',' << r.dofs << ',' << spec.strategy << ',' << spec.iterations << ','
            << spec.tolerance << ',' << threads << ',' << load << ',' << frames << ',' << percentile(r.frame_ms, 0.5)
            << ',' << mean << ',' << percentile(r.frame_ms, 0.95) << ',' << 1000.0 / mean << ',' << max_error / peak
            << ',' << final_error / peak << ',' << r.newton_iterations << ',' << r.linear_iterations << ','
            << r.factorizations << ',' << (r.factorizations ? r.factorization_ms / r.factorizations : 0.0) << ','
            << r.diverged << ',' << static_cast<double>(r.contacts) / frames << ',' << r.background_factorizations
            << '\n' << std::flush;
      }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") {
      std::cout << kUsage;
      return 0;
    }
  try {
    return main_checked(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "bench: " << e.what() << "\n";
    return 1;
  }
}
