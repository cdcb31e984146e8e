#include "liver_sim/linalg/cholmod_solver.h"

#include <dlfcn.h>
#include <omp.h>

#include <cmath>
#include <stdexcept>

namespace liver_sim {
namespace {

// CHOLMOD on the calling thread, process-wide (both settings belong to the process):
// - its own OpenMP loops (copies into the supernodes) ask for 4 threads whatever the machine,
//   and their barriers wait for any thread the system holds up, as the element loops' did
//   (doc/performance.md#threads-on-a-shared-computer). With no active OpenMP level allowed,
//   every OpenMP region of the process runs on the thread that meets it;
// - OpenBLAS (its dense blocks) keeps a thread pool of its own whose split of a block changes
//   the factor's last bits with its thread count, and so every later result. Other BLAS
//   libraries are left as they are.
void cholmod_on_calling_thread() {
  omp_set_max_active_levels(0);
  using SetThreads = void (*)(int);
  if (const auto set = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"))) set(1);
}

}  // namespace

CholmodSolver::CholmodSolver() {
  cholmod_on_calling_thread();
  cholmod_start(&common_);
  // Supernodal always (CHOLMOD would pick simplicial for tiny matrices): one factor layout for
  // forward_unit to walk.
  common_.supernodal = CHOLMOD_SUPERNODAL;
  // Both minimum degree and nested dissection are tried (the analysis is done once) and the
  // ordering with less fill kept: on the liver phantom METIS leaves 13% fewer nonzeros in L and
  // 31% fewer flops than AMD, which CHOLMOD's default would keep.
  common_.nmethods = 2;
  common_.method[0].ordering = CHOLMOD_AMD;
  common_.method[1].ordering = CHOLMOD_METIS;
  // Coarser supernodes than CHOLMOD's default amalgamation (nrelax 4/16/48, zrelax
  // 0.8/0.1/0.05): more explicit zeros in L, but more of the work in dense BLAS-3 blocks.
  // One core: refactorisation 10.4 -> 7.0 ms (cube 2k), 61 -> 45-50 ms (cube 10k and the
  // phantom); a triangular solve up to ~12% slower on the larger matrices. A net gain where the
  // factor is refreshed often (the phantom's real-time frames, full Newton, static solves).
  common_.nrelax[0] = 16;
  common_.nrelax[1] = 64;
  common_.nrelax[2] = 128;
  common_.zrelax[0] = 0.8;
  common_.zrelax[1] = 0.3;
  common_.zrelax[2] = 0.1;
  // LL^T also in the simplicial case, so that an indefinite matrix is reported, not factored.
  common_.final_ll = 1;
  // A non-positive-definite matrix is an expected outcome here (reported by factorize), not
  // something for CHOLMOD to print.
  common_.print = 0;
  common_.error_handler = nullptr;
}

CholmodSolver::~CholmodSolver() {
  cholmod_free_dense(&x_, &common_);
  cholmod_free_dense(&Y_, &common_);
  cholmod_free_dense(&E_, &common_);
  cholmod_free_dense(&half_, &common_);
  cholmod_free_factor(&factor_, &common_);
  cholmod_finish(&common_);
}

void CholmodSolver::analyze(int n, const std::vector<int>& column_start,
                            const std::vector<int>& row_index) {
  cholmod_free_factor(&factor_, &common_);
  factorized_ = false;
  A_ = cholmod_sparse{};
  A_.nrow = A_.ncol = static_cast<size_t>(n);
  A_.nzmax = row_index.size();
  A_.p = const_cast<int*>(column_start.data());
  A_.i = const_cast<int*>(row_index.data());
  A_.x = nullptr;
  A_.stype = 1;  // upper triangle stored
  A_.itype = CHOLMOD_INT;
  A_.xtype = CHOLMOD_PATTERN;
  A_.dtype = CHOLMOD_DOUBLE;
  A_.sorted = 1;
  A_.packed = 1;
  factor_ = cholmod_analyze(&A_, &common_);
  ++analyses_;
  if (!factor_ || common_.status < CHOLMOD_OK)
    throw std::runtime_error("CHOLMOD analysis failed (status " + std::to_string(common_.status) + ")");
  const int* perm = static_cast<const int*>(factor_->Perm);
  inverse_perm_.resize(n);
  for (int k = 0; k < n; ++k) inverse_perm_[perm[k]] = k;
  const int* super = static_cast<const int*>(factor_->super);
  supernode_of_.resize(n);
  for (size_t k = 0; k < factor_->nsuper; ++k)
    for (int j = super[k]; j < super[k + 1]; ++j) supernode_of_[j] = static_cast<int>(k);
  unit_work_.setZero(n);
  permuted_.resize(n);
}

bool CholmodSolver::factorize(const std::vector<double>& values) {
  if (!factor_) throw std::logic_error("CholmodSolver::factorize before analyze");
  factorized_ = false;
  for (double v : values)
    if (!std::isfinite(v)) return false;
  A_.x = const_cast<double*>(values.data());
  A_.xtype = CHOLMOD_REAL;
  const int ok = cholmod_factorize(&A_, factor_, &common_);
  ++factorizations_;
  A_.x = nullptr;
  A_.xtype = CHOLMOD_PATTERN;
  factorized_ = ok && common_.status == CHOLMOD_OK && factor_->minor == factor_->n;
  return factorized_;
}

void CholmodSolver::swap_factor(CholmodSolver& other) {
  if (!factor_ || !other.factor_ || factor_->n != other.factor_->n)
    throw std::logic_error("CholmodSolver::swap_factor between different patterns");
  // The analysis travels with the factor: each stays consistent even if the orderings differed.
  std::swap(factor_, other.factor_);
  std::swap(factorized_, other.factorized_);
  inverse_perm_.swap(other.inverse_perm_);
  supernode_of_.swap(other.supernode_of_);
  ++factorizations_;
  ++other.factorizations_;
}

void CholmodSolver::solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) {
  solve_columns(b.data(), 1);
  x = Eigen::Map<const Eigen::VectorXd>(static_cast<double*>(x_->x), b.size());
}

void CholmodSolver::solve(const Eigen::MatrixXd& B, Eigen::MatrixXd& X) {
  if (B.cols() == 0) {  // CHOLMOD reads a null array for no columns (a scene without targets)
    X.resize(B.rows(), 0);
    return;
  }
  solve_columns(B.data(), B.cols());
  X = Eigen::Map<const Eigen::MatrixXd>(static_cast<double*>(x_->x), B.rows(), B.cols());
}

void CholmodSolver::solve_columns(const double* b, long columns) {
  if (!factorized_) throw std::logic_error("CholmodSolver::solve without a valid factor");
  cholmod_dense B{};
  B.nrow = factor_->n;
  B.ncol = columns;
  B.nzmax = B.nrow * columns;
  B.d = B.nrow;
  B.x = const_cast<double*>(b);
  B.xtype = CHOLMOD_REAL;
  B.dtype = CHOLMOD_DOUBLE;
  cholmod_solve2(CHOLMOD_A, factor_, &B, nullptr, &x_, nullptr, &Y_, &E_, &common_);
}

cholmod_dense CholmodSolver::view(const double* data) const {
  cholmod_dense B{};
  B.nrow = factor_->n;
  B.ncol = 1;
  B.nzmax = B.nrow;
  B.d = B.nrow;
  B.x = const_cast<double*>(data);
  B.xtype = CHOLMOD_REAL;
  B.dtype = CHOLMOD_DOUBLE;
  return B;
}

void CholmodSolver::forward(const Eigen::VectorXd& b, Eigen::VectorXd& z) {
  if (!factorized_) throw std::logic_error("CholmodSolver::forward without a valid factor");
  const int* perm = static_cast<const int*>(factor_->Perm);
  for (Eigen::Index k = 0; k < b.size(); ++k) permuted_[k] = b[perm[k]];
  cholmod_dense B = view(permuted_.data());
  cholmod_solve2(CHOLMOD_L, factor_, &B, nullptr, &half_, nullptr, &Y_, &E_, &common_);
  z = Eigen::Map<const Eigen::VectorXd>(static_cast<double*>(half_->x), b.size());
}

void CholmodSolver::backward(const Eigen::VectorXd& z, Eigen::VectorXd& x) {
  if (!factorized_) throw std::logic_error("CholmodSolver::backward without a valid factor");
  cholmod_dense Z = view(z.data());
  cholmod_solve2(CHOLMOD_Lt, factor_, &Z, nullptr, &half_, nullptr, &Y_, &E_, &common_);
  const double* y = static_cast<const double*>(half_->x);
  const int* perm = static_cast<const int*>(factor_->Perm);
  x.resize(z.size());
  for (Eigen::Index k = 0; k < z.size(); ++k) x[perm[k]] = y[k];
}

void CholmodSolver::forward_unit(int i, SparseColumn& y) {
  if (!factorized_) throw std::logic_error("CholmodSolver::forward_unit without a valid factor");
  const int* super = static_cast<const int*>(factor_->super);
  const int* pi = static_cast<const int*>(factor_->pi);
  const int* px = static_cast<const int*>(factor_->px);
  const int* rows = static_cast<const int*>(factor_->s);
  const double* L = static_cast<const double*>(factor_->x);
  y.supernodes.clear();
  y.offsets.clear();
  int length = 0;
  const int start = inverse_perm_[i];
  for (int k = supernode_of_[start];;) {
    y.supernodes.push_back(k);
    y.offsets.push_back(length);
    length += super[k + 1] - super[k];
    const int nsrow = pi[k + 1] - pi[k];
    if (nsrow == super[k + 1] - super[k]) break;  // the root
    k = supernode_of_[rows[pi[k] + super[k + 1] - super[k]]];
  }
  y.values.resize(length);
  double* w = unit_work_.data();
  w[start] = 1.0;
  for (size_t p = 0; p < y.supernodes.size(); ++p) {
    const int k = y.supernodes[p];
    const int k1 = super[k], nscol = super[k + 1] - k1, nsrow = pi[k + 1] - pi[k];
    // The supernode's block: column-major nsrow x nscol, its first nscol rows the diagonal block.
    const Eigen::Map<const Eigen::MatrixXd> block(L + px[k], nsrow, nscol);
    Eigen::Map<Eigen::VectorXd> yk(y.values.data() + y.offsets[p], nscol);
    yk = Eigen::Map<const Eigen::VectorXd>(w + k1, nscol);
    block.topRows(nscol).triangularView<Eigen::Lower>().solveInPlace(yk);
    below_.noalias() = block.bottomRows(nsrow - nscol) * yk;
    for (int r = nscol; r < nsrow; ++r) w[rows[pi[k] + r]] -= below_[r - nscol];
    std::fill(w + k1, w + k1 + nscol, 0.0);
  }
}

double CholmodSolver::dot(const SparseColumn& a, const SparseColumn& b) const {
  // The shared part of two paths is the same chain of supernodes from their meeting point up,
  // stored last in both, in the same order.
  size_t i = a.supernodes.size(), j = b.supernodes.size();
  while (i > 0 && j > 0 && a.supernodes[i - 1] == b.supernodes[j - 1]) --i, --j;
  if (i == a.supernodes.size()) return 0.0;
  const Eigen::Index length = a.values.size() - a.offsets[i];
  return a.values.tail(length).dot(b.values.tail(length));
}

double CholmodSolver::dot(const SparseColumn& a, const Eigen::VectorXd& z) const {
  const int* super = static_cast<const int*>(factor_->super);
  double s = 0;
  for (size_t p = 0; p < a.supernodes.size(); ++p) {
    const int k = a.supernodes[p], nscol = super[k + 1] - super[k];
    s += a.values.segment(a.offsets[p], nscol).dot(z.segment(super[k], nscol));
  }
  return s;
}

void CholmodSolver::add(const SparseColumn& a, double s, Eigen::VectorXd& z) const {
  const int* super = static_cast<const int*>(factor_->super);
  for (size_t p = 0; p < a.supernodes.size(); ++p) {
    const int k = a.supernodes[p], nscol = super[k + 1] - super[k];
    z.segment(super[k], nscol) += s * a.values.segment(a.offsets[p], nscol);
  }
}

double CholmodSolver::factor_nonzeros() const { return common_.lnz; }

}  // namespace liver_sim
