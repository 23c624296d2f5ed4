#include "trailnav/navigation/slam/sparse_cholesky.hpp"

#include <cholmod.h>

#include <cstdlib>
#include <cstring>
#include <mutex>

#include "trailnav/navigation/slam/arena.hpp"

namespace trailnav::slam {
namespace {

// The arena CHOLMOD allocates from on this thread while a SparseCholesky
// calls it; null otherwise (another SuiteSparse user in the process, such as
// Ceres in the side-by-side benchmark, then gets the C heap as usual).
thread_local Arena* t_arena = nullptr;

void* hook_malloc(std::size_t n) { return t_arena != nullptr ? t_arena->allocate(n) : std::malloc(n); }
void* hook_calloc(std::size_t count, std::size_t size) {
  if (t_arena == nullptr) return std::calloc(count, size);
  if (size != 0 && count > static_cast<std::size_t>(-1) / size) return nullptr;
  void* p = t_arena->allocate(count * size);
  if (p != nullptr) std::memset(p, 0, count * size);
  return p;
}
void* hook_realloc(void* p, std::size_t n) {
  if (t_arena != nullptr && (p == nullptr || t_arena->owns(p))) return t_arena->reallocate(p, n);
  return std::realloc(p, n);
}
void hook_free(void* p) {
  if (t_arena != nullptr && t_arena->owns(p)) {
    t_arena->release(p);
  } else {
    std::free(p);
  }
}

void install_hooks() {
  static std::once_flag once;
  std::call_once(once, [] {
    SuiteSparse_config.malloc_func = hook_malloc;
    SuiteSparse_config.calloc_func = hook_calloc;
    SuiteSparse_config.realloc_func = hook_realloc;
    SuiteSparse_config.free_func = hook_free;
  });
}

struct Scope {
  explicit Scope(Arena* a) noexcept : saved(t_arena) { t_arena = a; }
  ~Scope() { t_arena = saved; }
  Arena* saved;
};

}  // namespace

struct SparseCholesky::Impl {
  Arena* arena = nullptr;
  cholmod_common common{};
  cholmod_sparse* a = nullptr;
  cholmod_factor* l = nullptr;
  cholmod_dense* b = nullptr;
  cholmod_dense* x = nullptr;
  cholmod_dense* y = nullptr;
  cholmod_dense* e = nullptr;
  bool started = false;

  void free_all() {
    if (l != nullptr) cholmod_free_factor(&l, &common);
    if (a != nullptr) cholmod_free_sparse(&a, &common);
    if (b != nullptr) cholmod_free_dense(&b, &common);
    if (x != nullptr) cholmod_free_dense(&x, &common);
    if (y != nullptr) cholmod_free_dense(&y, &common);
    if (e != nullptr) cholmod_free_dense(&e, &common);
  }
};

SparseCholesky::SparseCholesky(Arena& arena, Factorisation kind) : impl_(new Impl) {
  install_hooks();
  impl_->arena = &arena;
  Scope s(impl_->arena);
  cholmod_start(&impl_->common);
  impl_->common.print = 0;
  impl_->common.supernodal = kind == Factorisation::simplicial ? CHOLMOD_SIMPLICIAL : CHOLMOD_AUTO;
  impl_->started = true;
}

SparseCholesky::~SparseCholesky() {
  Scope s(impl_->arena);
  impl_->free_all();
  if (impl_->started) cholmod_finish(&impl_->common);
  delete impl_;
}

namespace {
bool out_of_memory(const cholmod_common& c) { return c.status == CHOLMOD_OUT_OF_MEMORY || c.status == CHOLMOD_TOO_LARGE; }
}  // namespace

bool SparseCholesky::analyse(int n, std::span<const int> colptr, std::span<const int> rows, std::string& error) {
  Scope s(impl_->arena);
  impl_->free_all();
  n_ = 0;
  const auto nnz = static_cast<std::size_t>(colptr[static_cast<std::size_t>(n)]);
  impl_->a = cholmod_allocate_sparse(static_cast<std::size_t>(n), static_cast<std::size_t>(n), nnz, 1, 1, 1, CHOLMOD_REAL,
                                     &impl_->common);
  if (impl_->a == nullptr) {
    error = "the solver's memory (" + std::to_string(impl_->arena->capacity() >> 20) + " MiB) cannot hold the matrix";
    return false;
  }
  std::memcpy(impl_->a->p, colptr.data(), sizeof(int) * (static_cast<std::size_t>(n) + 1));
  std::memcpy(impl_->a->i, rows.data(), sizeof(int) * nnz);
  std::memset(impl_->a->x, 0, sizeof(double) * nnz);
  impl_->l = cholmod_analyze(impl_->a, &impl_->common);
  if (impl_->l == nullptr) {
    error = out_of_memory(impl_->common)
                ? "the solver's memory (" + std::to_string(impl_->arena->capacity() >> 20) + " MiB) cannot hold the factor's analysis"
                : "the sparse Cholesky could not analyse the matrix (CHOLMOD status " + std::to_string(impl_->common.status) + ")";
    return false;
  }
  impl_->b = cholmod_zeros(static_cast<std::size_t>(n), 1, CHOLMOD_REAL, &impl_->common);
  if (impl_->b == nullptr) {
    error = "the solver's memory cannot hold the right-hand side";
    return false;
  }
  n_ = n;
  return true;
}

std::span<double> SparseCholesky::values() noexcept {
  if (impl_->a == nullptr) return {};
  return {static_cast<double*>(impl_->a->x), static_cast<std::size_t>(static_cast<int*>(impl_->a->p)[n_])};
}

bool SparseCholesky::factorise(std::string& error) {
  Scope s(impl_->arena);
  if (impl_->l == nullptr) {
    error = "no pattern analysed";
    return false;
  }
  const int ok = cholmod_factorize(impl_->a, impl_->l, &impl_->common);
  if (ok == 0 || out_of_memory(impl_->common)) {
    error = "the solver's memory (" + std::to_string(impl_->arena->capacity() >> 20) + " MiB) cannot hold the factor";
    return false;
  }
  if (impl_->common.status == CHOLMOD_NOT_POSDEF) {
    error = "not positive definite";
    return false;
  }
  return true;
}

bool SparseCholesky::solve(std::span<const double> b, std::span<double> x, std::string& error) {
  Scope s(impl_->arena);
  std::memcpy(impl_->b->x, b.data(), sizeof(double) * static_cast<std::size_t>(n_));
  if (cholmod_solve2(CHOLMOD_A, impl_->l, impl_->b, nullptr, &impl_->x, nullptr, &impl_->y, &impl_->e, &impl_->common) == 0) {
    error = "the solver's memory cannot hold the solve's workspace";
    return false;
  }
  std::memcpy(x.data(), impl_->x->x, sizeof(double) * static_cast<std::size_t>(n_));
  return true;
}

bool SparseCholesky::supernodal() const noexcept { return impl_->l != nullptr && impl_->l->is_super != 0; }

double SparseCholesky::factor_nonzeros() const noexcept { return impl_->common.lnz; }

}  // namespace trailnav::slam
