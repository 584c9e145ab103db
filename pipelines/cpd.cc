// Coherent Point Drift (Myronenko & Song 2010). Equations: see pipelines/cpd.h and docs/cpd.md.
#include "pipelines/cpd.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <numbers>
#include <sstream>
#include <vector>

#include "common/error.h"

#include <omp.h>

namespace arthrosim::pipelines {

std::string to_string(CpdStatus status) {
  switch (status) {
    case CpdStatus::kConverged: return "converged";
    case CpdStatus::kSigmaFloor: return "sigma2 floor reached (sets coincide)";
    case CpdStatus::kMaxIterations: return "max iterations reached (not converged)";
  }
  return "unknown";
}

// ---------------------------------------------------------------------------------------
// CpdTransform
// ---------------------------------------------------------------------------------------

Eigen::MatrixXd CpdTransform::apply(const Eigen::MatrixXd& Z) const {
  const Eigen::Index D = A.rows();
  if (Z.cols() != D)
    throw common::InputError("CpdTransform::apply: expected points with " + std::to_string(D) + " columns, found " +
                     std::to_string(Z.cols()));
  Eigen::MatrixXd U = (Z * A.transpose()).rowwise() + b.transpose();
  const Eigen::Index K = centres.rows();
  if (K > 0) {
    const double inv2b2 = 1.0 / (2.0 * beta * beta);
    Eigen::MatrixXd disp = Eigen::MatrixXd::Zero(U.rows(), D);
#pragma omp parallel for schedule(static) if (U.rows() * K > 20000)
    for (Eigen::Index i = 0; i < U.rows(); ++i) {
      for (Eigen::Index k = 0; k < K; ++k) {
        const double g = std::exp(-(U.row(i) - centres.row(k)).squaredNorm() * inv2b2);
        disp.row(i) += g * weights.row(k);
      }
    }
    U += disp;
  }
  Eigen::MatrixXd out = out_scale * U;
  if (out_offset.size() == D) out.rowwise() += out_offset.transpose();
  return out;
}

Eigen::MatrixXd CpdTransform::jacobian(const Eigen::VectorXd& y) const {
  const Eigen::Index D = A.rows();
  if (y.size() != D)
    throw common::InputError("CpdTransform::jacobian: expected a point of size " + std::to_string(D) + ", found " +
                     std::to_string(y.size()));
  const Eigen::VectorXd u = A * y + b;
  Eigen::MatrixXd J = Eigen::MatrixXd::Identity(D, D);
  const double inv_b2 = 1.0 / (beta * beta);
  for (Eigen::Index k = 0; k < centres.rows(); ++k) {
    const Eigen::VectorXd r = u - centres.row(k).transpose();
    const double g = std::exp(-0.5 * r.squaredNorm() * inv_b2);
    // d/du [g_k w_k] = w_k grad g_k^T, grad g_k = -(u - c_k) g_k / beta^2.
    J.noalias() -= (g * inv_b2) * weights.row(k).transpose() * r.transpose();
  }
  return out_scale * J * A;
}

namespace {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::VectorXd;

constexpr int kChunks = 16;  // fixed work split => results independent of the thread count

// Runs Eigen's dense kernels single-threaded within a scope. Eigen's parallel GEMM picks its
// blocking from omp_get_max_threads(), which would make results depend on the thread count, and
// many tiny parallel regions stall badly on a loaded machine. omp_set_num_threads changes only
// the calling thread's ICV, so other threads of the program are unaffected.
class SerialEigenScope {
 public:
  SerialEigenScope() : saved_(omp_get_max_threads()) { omp_set_num_threads(1); }
  ~SerialEigenScope() { omp_set_num_threads(saved_); }
  SerialEigenScope(const SerialEigenScope&) = delete;
  SerialEigenScope& operator=(const SerialEigenScope&) = delete;

 private:
  int saved_;
};

struct Normalization {
  Eigen::RowVectorXd mean;
  double scale = 1.0;
};

Normalization compute_normalization(const MatrixXd& P, bool on) {
  Normalization n;
  n.mean = Eigen::RowVectorXd::Zero(P.cols());
  if (!on) return n;
  n.mean = P.colwise().mean();
  n.scale = std::sqrt((P.rowwise() - n.mean).squaredNorm() / static_cast<double>(P.rows()));
  return n;
}

// Uniform grid over a point set (rows of a row-major array), cell size h. Points are sorted
// by cell with a stable counting sort, so every query visits points in a fixed order.
class UniformGrid {
 public:
  UniformGrid(const std::vector<double>& pts, Index count, int D, double radius)
      : D_(D), radius2_(radius * radius) {
    lo_.assign(D, std::numeric_limits<double>::infinity());
    std::vector<double> hi(D, -std::numeric_limits<double>::infinity());
    for (Index i = 0; i < count; ++i)
      for (int d = 0; d < D; ++d) {
        lo_[d] = std::min(lo_[d], pts[i * D + d]);
        hi[d] = std::max(hi[d], pts[i * D + d]);
      }
    // Cell size >= radius (so the 3^D neighbouring cells cover the ball), enlarged until the
    // grid has at most ~2 count + 64 cells (memory linear in the point count).
    const double max_cells = 2.0 * static_cast<double>(count) + 64.0;
    h_ = radius;
    for (;;) {
      double total = 1.0;
      for (int d = 0; d < D; ++d) total *= std::floor((hi[d] - lo_[d]) / h_) + 1.0;
      if (total <= max_cells) break;
      h_ *= 1.5;
    }
    dims_.resize(D);
    for (int d = 0; d < D; ++d) dims_[d] = static_cast<int64_t>(std::floor((hi[d] - lo_[d]) / h_)) + 1;
    int64_t ncells = 1;
    for (int d = 0; d < D; ++d) ncells *= dims_[d];
    start_.assign(static_cast<size_t>(ncells) + 1, 0);
    std::vector<int64_t> cell(static_cast<size_t>(count));
    for (Index i = 0; i < count; ++i) {
      int64_t c = 0;
      for (int d = D - 1; d >= 0; --d) c = c * dims_[d] + coord(pts[i * D + d], d);
      cell[i] = c;
      ++start_[static_cast<size_t>(c) + 1];
    }
    for (size_t c = 1; c < start_.size(); ++c) start_[c] += start_[c - 1];
    order_.resize(static_cast<size_t>(count));
    std::vector<int64_t> fill(start_.begin(), start_.end() - 1);
    for (Index i = 0; i < count; ++i) order_[static_cast<size_t>(fill[static_cast<size_t>(cell[i])]++)] =
        static_cast<int>(i);
  }

  // Calls f(index, squared distance) for every point within the radius of q, in a fixed order.
  template <class F>
  void for_each_near(const double* q, const std::vector<double>& pts, F&& f) const {
    int64_t cmin[3] = {0, 0, 0}, cmax[3] = {0, 0, 0};
    for (int d = 0; d < D_; ++d) {
      const double c = std::floor((q[d] - lo_[d]) / h_);
      // Cells c-1..c+1 cover [q - h, q + h] since h >= radius; clamp to the grid.
      const double a = std::max(c - 1.0, 0.0), b = std::min(c + 1.0, static_cast<double>(dims_[d] - 1));
      if (a > b) return;
      cmin[d] = static_cast<int64_t>(a);
      cmax[d] = static_cast<int64_t>(b);
    }
    int64_t idx[3] = {cmin[0], cmin[1], D_ > 2 ? cmin[2] : 0};
    for (;;) {
      int64_t c = 0;
      for (int d = D_ - 1; d >= 0; --d) c = c * dims_[d] + idx[d];
      for (int64_t k = start_[c]; k < start_[c + 1]; ++k) {
        const int m = order_[static_cast<size_t>(k)];
        double r2 = 0.0;
        for (int d = 0; d < D_; ++d) {
          const double t = q[d] - pts[static_cast<size_t>(m) * D_ + d];
          r2 += t * t;
        }
        if (r2 <= radius2_) f(m, r2);
      }
      int d = 0;
      while (d < D_ && ++idx[d] > cmax[d]) {
        idx[d] = cmin[d];
        ++d;
      }
      if (d == D_) break;
    }
  }

 private:
  int64_t coord(double x, int d) const {
    return std::clamp<int64_t>(static_cast<int64_t>(std::floor((x - lo_[d]) / h_)), 0, dims_[d] - 1);
  }
  int D_;
  double radius2_;
  double h_ = 1.0;
  std::vector<double> lo_;
  std::vector<int64_t> dims_;
  std::vector<int64_t> start_;
  std::vector<int> order_;
};

std::vector<double> row_major(const MatrixXd& P) {
  std::vector<double> out(static_cast<size_t>(P.size()));
  for (Index i = 0; i < P.rows(); ++i)
    for (Index d = 0; d < P.cols(); ++d) out[static_cast<size_t>(i * P.cols() + d)] = P(i, d);
  return out;
}

// A^T B and A B with the rows of A (and B) split into kChunks fixed blocks, each multiplied
// inside one OpenMP thread and the partial products summed in block order. Eigen's own
// parallel GEMM chooses its blocking from the thread count, which would make the low-rank
// M-step depend on the number of threads; this keeps it bit-identical.
MatrixXd atb_fixed(const MatrixXd& A, const MatrixXd& B) {
  const Index n = A.rows();
  const int chunks = static_cast<int>(std::min<Index>(kChunks, std::max<Index>(n, 1)));
  std::vector<MatrixXd> part(static_cast<size_t>(chunks));
#pragma omp parallel for schedule(dynamic, 1) if (n * A.cols() * B.cols() > 200000)
  for (int c = 0; c < chunks; ++c) {
    const Index r0 = n * c / chunks, r1 = n * (c + 1) / chunks;
    part[static_cast<size_t>(c)].noalias() = A.middleRows(r0, r1 - r0).transpose() * B.middleRows(r0, r1 - r0);
  }
  MatrixXd out = MatrixXd::Zero(A.cols(), B.cols());
  for (const MatrixXd& p : part) out += p;
  return out;
}

MatrixXd ab_fixed(const MatrixXd& A, const MatrixXd& B) {
  const Index n = A.rows();
  MatrixXd out(n, B.cols());
  const int chunks = static_cast<int>(std::min<Index>(kChunks, std::max<Index>(n, 1)));
#pragma omp parallel for schedule(dynamic, 1) if (n * A.cols() * B.cols() > 200000)
  for (int c = 0; c < chunks; ++c) {
    const Index r0 = n * c / chunks, r1 = n * (c + 1) / chunks;
    out.middleRows(r0, r1 - r0).noalias() = A.middleRows(r0, r1 - r0) * B;
  }
  return out;
}

struct EStep {
  VectorXd P1, Pt1;
  MatrixXd PX;
  double nll = 0.0;  // -sum_n log(den_n) + N D/2 log s^2
  int unmatched = 0;
};

// E-step of CPD without storing P. For each data point x_n (in chunk order, fixed) the kernel
// values to its neighbours are shifted by the closest squared distance (a log-sum-exp shift: the
// same factor multiplies numerator and denominator, so P is unchanged but nothing underflows to
// 0/0 when w = 0), then scattered into the chunk's private P1/PX buffer; the chunk buffers are
// summed in chunk order.
//
// Weighted form (used by the binned E-step): data point n stands for wx[n] coincident points
// and centroid m for wy[m] coincident centroids; x must then hold wx-weighted centroids and
// P1/PX/Pt1 are per represented point. Ntot/Mtot are the true set sizes (for c and L).
EStep e_step(const std::vector<double>& x, Index N, const std::vector<double>& ty, Index M, int D, double sigma2,
             double w, bool truncated, double truncation_sigmas, const std::vector<double>* wx = nullptr,
             const std::vector<double>* wy = nullptr, double Ntot = 0.0, double Mtot = 0.0) {
  if (Ntot <= 0.0) Ntot = static_cast<double>(N);
  if (Mtot <= 0.0) Mtot = static_cast<double>(M);
  const double two_s2 = 2.0 * sigma2;
  const double c = w > 0.0 ? std::pow(2.0 * std::numbers::pi * sigma2, 0.5 * D) * w / (1.0 - w) * Mtot / Ntot
                           : 0.0;
  const double log_c = c > 0.0 ? std::log(c) : -std::numeric_limits<double>::infinity();
  std::unique_ptr<UniformGrid> grid;
  if (truncated) grid = std::make_unique<UniformGrid>(ty, M, D, truncation_sigmas * std::sqrt(sigma2));

  const int chunks = static_cast<int>(std::min<Index>(kChunks, N));
  const int stride = D + 1;
  std::vector<std::vector<double>> acc(static_cast<size_t>(chunks));
  std::vector<double> chunk_nll(static_cast<size_t>(chunks), 0.0);
  std::vector<int> chunk_unmatched(static_cast<size_t>(chunks), 0);
  EStep out;
  out.Pt1 = VectorXd::Zero(N);

#pragma omp parallel for schedule(dynamic, 1) if (static_cast<double>(M) * static_cast<double>(N) > 2.0e5)
  for (int ch = 0; ch < chunks; ++ch) {
    std::vector<double>& buf = acc[static_cast<size_t>(ch)];
    buf.assign(static_cast<size_t>(M * stride), 0.0);
    std::vector<int> nb_index;
    std::vector<double> nb_val;
    const Index n0 = N * ch / chunks, n1 = N * (ch + 1) / chunks;
    double nll = 0.0;
    int unmatched = 0;
    for (Index n = n0; n < n1; ++n) {
      const double* xn = &x[static_cast<size_t>(n * D)];
      const double wn = wx ? (*wx)[static_cast<size_t>(n)] : 1.0;
      nb_index.clear();
      nb_val.clear();
      auto collect = [&](int m, double r2) {
        nb_index.push_back(m);
        nb_val.push_back(r2);
      };
      if (truncated) {
        grid->for_each_near(xn, ty, collect);
      } else {
        for (Index m = 0; m < M; ++m) {
          double r2 = 0.0;
          for (int d = 0; d < D; ++d) {
            const double t = xn[d] - ty[static_cast<size_t>(m * D + d)];
            r2 += t * t;
          }
          collect(static_cast<int>(m), r2);
        }
      }
      if (nb_index.empty()) {
        // No centroid within the cutoff: P_mn = 0 (each true value < exp(-k^2/2) / c).
        if (c > 0.0) {
          nll -= wn * log_c;
        } else {
          unmatched += static_cast<int>(wn);
        }
        continue;
      }
      double r2min = nb_val[0];
      for (double v : nb_val) r2min = std::min(r2min, v);
      double S = 0.0;
      for (size_t k = 0; k < nb_val.size(); ++k) {
        nb_val[k] = std::exp(-(nb_val[k] - r2min) / two_s2);
        S += wy ? (*wy)[static_cast<size_t>(nb_index[k])] * nb_val[k] : nb_val[k];
      }
      const double a = r2min / two_s2;           // den = exp(-a) (S + c exp(a))
      const double c_shift = std::exp(log_c + a);  // may be +inf: then every P_mn = 0 (exact limit)
      const double den = S + c_shift;
      // log den_n = logaddexp(-a + log S, log c)
      const double u = -a + std::log(S);
      const double lden = std::isinf(log_c) ? u : std::max(u, log_c) + std::log1p(std::exp(-std::abs(u - log_c)));
      nll -= wn * lden;
      out.Pt1(n) = S / den;
      for (size_t k = 0; k < nb_index.size(); ++k) {
        const double p = nb_val[k] / den;
        const double pw = wn * p;
        double* dst = &buf[static_cast<size_t>(nb_index[k]) * stride];
        dst[0] += pw;
        for (int d = 0; d < D; ++d) dst[d + 1] += pw * xn[d];
      }
    }
    chunk_nll[static_cast<size_t>(ch)] = nll;
    chunk_unmatched[static_cast<size_t>(ch)] = unmatched;
  }
  out.P1 = VectorXd::Zero(M);
  out.PX = MatrixXd::Zero(M, D);
  for (int ch = 0; ch < chunks; ++ch) {
    const std::vector<double>& buf = acc[static_cast<size_t>(ch)];
    for (Index m = 0; m < M; ++m) {
      out.P1(m) += buf[static_cast<size_t>(m * stride)];
      for (int d = 0; d < D; ++d) out.PX(m, d) += buf[static_cast<size_t>(m * stride + d + 1)];
    }
    out.nll += chunk_nll[static_cast<size_t>(ch)];
    out.unmatched += chunk_unmatched[static_cast<size_t>(ch)];
  }
  out.nll += 0.5 * Ntot * D * std::log(sigma2);
  return out;
}

// Points grouped by the cells of a uniform grid of size h (cells numbered lexicographically
// over the bounding box, clusters in cell order, centroids summed in point order).
struct Bins {
  std::vector<double> centroid;  // K x D row-major
  std::vector<double> weight;    // K
  std::vector<int> cluster;      // point -> cluster
  Index count = 0;
};

// Returns false (no binning) if the bounding box has more than max_cells cells of size h.
bool bin_points(const std::vector<double>& p, Index n, int D, double h, double max_cells, Bins& b) {
  std::vector<double> lo(D, std::numeric_limits<double>::infinity()), hi(D, -std::numeric_limits<double>::infinity());
  for (Index i = 0; i < n; ++i)
    for (int d = 0; d < D; ++d) {
      lo[d] = std::min(lo[d], p[static_cast<size_t>(i * D + d)]);
      hi[d] = std::max(hi[d], p[static_cast<size_t>(i * D + d)]);
    }
  std::vector<int64_t> dims(D);
  double total = 1.0;
  for (int d = 0; d < D; ++d) {
    const double cells = std::floor((hi[d] - lo[d]) / h) + 1.0;
    total *= cells;
    if (!(total <= max_cells)) return false;
    dims[d] = static_cast<int64_t>(cells);
  }
  std::vector<int> cell_to_cluster(static_cast<size_t>(total), -1);
  std::vector<int64_t> key(static_cast<size_t>(n));
  for (Index i = 0; i < n; ++i) {
    int64_t k = 0;
    for (int d = D - 1; d >= 0; --d) {
      const int64_t c = std::clamp<int64_t>(
          static_cast<int64_t>(std::floor((p[static_cast<size_t>(i * D + d)] - lo[d]) / h)), 0, dims[d] - 1);
      k = k * dims[d] + c;
    }
    key[static_cast<size_t>(i)] = k;
    cell_to_cluster[static_cast<size_t>(k)] = 0;
  }
  b.count = 0;
  for (int& c : cell_to_cluster)
    if (c == 0) c = static_cast<int>(b.count++);
  b.centroid.assign(static_cast<size_t>(b.count * D), 0.0);
  b.weight.assign(static_cast<size_t>(b.count), 0.0);
  b.cluster.resize(static_cast<size_t>(n));
  for (Index i = 0; i < n; ++i) {
    const int c = cell_to_cluster[static_cast<size_t>(key[static_cast<size_t>(i)])];
    b.cluster[static_cast<size_t>(i)] = c;
    b.weight[static_cast<size_t>(c)] += 1.0;
    for (int d = 0; d < D; ++d) b.centroid[static_cast<size_t>(c) * D + d] += p[static_cast<size_t>(i * D + d)];
  }
  for (Index c = 0; c < b.count; ++c)
    for (int d = 0; d < D; ++d) b.centroid[static_cast<size_t>(c * D + d)] /= b.weight[static_cast<size_t>(c)];
  return true;
}

// Binned E-step for large sigma: both sets are replaced by the centroids of grid cells of size
// sigma / bins_per_sigma (weighted by their point counts); every point of a cell receives its
// cell's posterior sums. Used only when it reduces the pair count by 4x or more. Returns false
// when binning does not pay.
bool binned_e_step(const std::vector<double>& x, Index N, const std::vector<double>& ty, Index M, int D,
                   double sigma2, const CpdOptions& opt, EStep& out) {
  const double h = std::sqrt(sigma2) / opt.bins_per_sigma;
  Bins bx, by;
  if (!bin_points(x, N, D, h, 4.0 * static_cast<double>(N), bx)) return false;
  if (!bin_points(ty, M, D, h, 4.0 * static_cast<double>(M), by)) return false;
  if (static_cast<double>(bx.count) * static_cast<double>(by.count) >
      0.25 * static_cast<double>(N) * static_cast<double>(M))
    return false;
  const EStep e = e_step(bx.centroid, bx.count, by.centroid, by.count, D, sigma2, opt.w, true, opt.truncation_sigmas,
                         &bx.weight, &by.weight, static_cast<double>(N), static_cast<double>(M));
  out.nll = e.nll;
  out.unmatched = e.unmatched;
  out.Pt1.resize(N);
  for (Index n = 0; n < N; ++n) out.Pt1(n) = e.Pt1(bx.cluster[static_cast<size_t>(n)]);
  out.P1.resize(M);
  out.PX.resize(M, D);
  // A centroid at offset delta from its cell's centroid sees (to first order, for data that is
  // locally translation-invariant at the cell scale h << sigma) the same posterior shifted by
  // delta: PX_m = PX_cell + P1_cell delta. Without this shift every member of a cell would be
  // pulled to one common target, a spurious contraction at the cell scale that stalls the EM
  // (measured on the benchmark: a false fixed point at s^2 ~ 0.12).
  for (Index m = 0; m < M; ++m) {
    const int c = by.cluster[static_cast<size_t>(m)];
    out.P1(m) = e.P1(c);
    for (int d = 0; d < D; ++d)
      out.PX(m, d) = e.PX(c, d) + e.P1(c) * (ty[static_cast<size_t>(m * D + d)] -
                                              by.centroid[static_cast<size_t>(c) * D + d]);
  }
  return true;
}

double initial_sigma2(const MatrixXd& X, const MatrixXd& TY) {
  // sum_{m,n} |x_n - y_m|^2 / (D M N) in O(M + N).
  const double M = static_cast<double>(TY.rows()), N = static_cast<double>(X.rows());
  const double v = M * X.squaredNorm() + N * TY.squaredNorm() -
                   2.0 * X.colwise().sum().dot(TY.colwise().sum());
  return v / (static_cast<double>(X.cols()) * M * N);
}

void check_finite(double v, const char* what, int iteration) {
  if (!std::isfinite(v)) {
    std::ostringstream s;
    s << "cpd_register: " << what << " is not finite (" << v << ") at EM iteration " << iteration;
    throw common::NumericalError(s.str());
  }
}

// Shared EM driver. `mstep(e, sigma2)` updates the model, returns the new TY through `ty`
// and the new sigma2; `regularizer()` gives the extra NLL term.
struct EmOutcome {
  CpdStatus status = CpdStatus::kMaxIterations;
  int iterations = 0;
  double sigma2 = 0.0, nll = 0.0, rel = 0.0;
  VectorXd P1;
  int unmatched = 0;
  int binned = 0;
  bool truncated = false;
};

// The EM loop's outcome into the result (status, iterations, sigma2, ...).
void copy_em_outcome(const EmOutcome& em, CpdResult& res) {
  res.status = em.status;
  res.iterations = em.iterations;
  res.sigma2 = em.sigma2;
  res.negative_log_likelihood = em.nll;
  res.relative_change = em.rel;
  res.match_weight = em.P1;
  res.truncated_estep = em.truncated;
  res.unmatched_points = em.unmatched;
  res.binned_estep_iterations = em.binned;
}

template <class MStep, class Reg>
EmOutcome run_em(const MatrixXd& X, MatrixXd& TY, const CpdOptions& opt, MStep&& mstep, Reg&& regularizer) {
  const Index N = X.rows(), M = TY.rows();
  const int D = static_cast<int>(X.cols());
  const std::vector<double> x = row_major(X);
  bool truncated = false;
  switch (opt.estep) {
    case CpdEStep::kFull: truncated = false; break;
    case CpdEStep::kTruncated: truncated = true; break;
    case CpdEStep::kAuto:
      truncated = static_cast<double>(M) * static_cast<double>(N) > opt.full_estep_max_pairs;
      break;
  }
  EmOutcome o;
  o.truncated = truncated;
  double sigma2 = opt.sigma2_initial > 0.0 ? opt.sigma2_initial : initial_sigma2(X, TY);
  check_finite(sigma2, "initial sigma2", 0);
  if (!(sigma2 > 0.0)) {
    // The sets coincide point for point already.
    o.status = CpdStatus::kSigmaFloor;
    o.P1 = VectorXd::Ones(M);
    o.sigma2 = sigma2;
    return o;
  }
  double nll_old = std::numeric_limits<double>::quiet_NaN();
  for (int it = 0;; ++it) {
    const std::vector<double> ty = row_major(TY);
    EStep e;
    if (truncated && opt.bins_per_sigma > 0.0 && binned_e_step(x, N, ty, M, D, sigma2, opt, e)) {
      ++o.binned;
    } else {
      e = e_step(x, N, ty, M, D, sigma2, opt.w, truncated, opt.truncation_sigmas);
    }
    const double nll = e.nll + regularizer();
    check_finite(nll, "negative log-likelihood", it);
    o.nll = nll;
    o.P1 = e.P1;
    o.unmatched = e.unmatched;
    o.sigma2 = sigma2;
    o.iterations = it;
    if (it > 0) {
      o.rel = std::abs(nll - nll_old) / std::max(std::abs(nll), std::numeric_limits<double>::min());
      if (o.rel < opt.tolerance) {
        o.status = CpdStatus::kConverged;
        return o;
      }
    }
    if (it == opt.max_iterations) {
      o.status = CpdStatus::kMaxIterations;
      return o;
    }
    if (!(e.P1.sum() > 0.0)) {
      throw common::NumericalError("cpd_register: no correspondences (sum of P = 0) at EM iteration " + std::to_string(it) +
                           ": the sets are too far apart for sigma2 = " + std::to_string(sigma2));
    }
    sigma2 = mstep(e, TY, sigma2);
    check_finite(sigma2, "sigma2", it);
    if (!TY.allFinite()) throw common::NumericalError("cpd_register: transformed points not finite at EM iteration " +
                                              std::to_string(it));
    nll_old = nll;
    if (sigma2 < opt.sigma2_floor) {
      o.status = CpdStatus::kSigmaFloor;
      o.iterations = it + 1;
      o.sigma2 = std::max(sigma2, 0.0);
      return o;
    }
  }
}

// Weighted statistics shared by the rigid and affine M-steps.
struct Moments {
  double Np;
  Eigen::RowVectorXd mu_x, mu_y;
  MatrixXd A;       // X^T P^T Y - Np mu_x mu_y^T (centred cross term)
  double xPx;       // sum_n Pt1_n |x_n - mu_x|^2
};

Moments moments(const EStep& e, const MatrixXd& X, const MatrixXd& Y) {
  Moments m;
  m.Np = e.P1.sum();
  m.mu_x = (e.Pt1.transpose() * X) / m.Np;
  m.mu_y = (e.P1.transpose() * Y) / m.Np;
  m.A = atb_fixed(e.PX, Y) - m.Np * m.mu_x.transpose() * m.mu_y;
  m.xPx = e.Pt1.dot((X.rowwise() - m.mu_x).rowwise().squaredNorm());
  return m;
}

struct RigidState {
  MatrixXd R;
  double s = 1.0;
  VectorXd t;
};

struct RigidRun {
  RigidState st;
  EmOutcome em;
  MatrixXd TY;
};

RigidRun run_rigid(const MatrixXd& X, const MatrixXd& Y, const CpdOptions& opt, const RigidState& init) {
  RigidRun run;
  run.st = init;
  const int D = static_cast<int>(X.cols());
  run.TY = ((Y * run.st.R.transpose()) * run.st.s).rowwise() + run.st.t.transpose();
  auto mstep = [&](const EStep& e, MatrixXd& TY, double) {
    const Moments mo = moments(e, X, Y);
    Eigen::JacobiSVD<MatrixXd> svd(mo.A, Eigen::ComputeFullU | Eigen::ComputeFullV);
    VectorXd C = VectorXd::Ones(D);
    C(D - 1) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
    run.st.R = svd.matrixU() * C.asDiagonal() * svd.matrixV().transpose();
    const double trAR = svd.singularValues().dot(C);
    const double yPy = e.P1.dot((Y.rowwise() - mo.mu_y).rowwise().squaredNorm());
    run.st.s = opt.estimate_scale ? trAR / yPy : 1.0;
    run.st.t = mo.mu_x.transpose() - run.st.s * run.st.R * mo.mu_y.transpose();
    TY = ((Y * run.st.R.transpose()) * run.st.s).rowwise() + run.st.t.transpose();
    // sigma2 = (tr(Xh^T d(Pt1) Xh) - s tr(A^T R)) / (Np D); with fixed scale the cross term
    // must be expanded: |x - sRy - t|^2 summed = xPx - 2 s trAR + s^2 yPy.
    const double num = opt.estimate_scale ? mo.xPx - run.st.s * trAR
                                          : mo.xPx - 2.0 * run.st.s * trAR + run.st.s * run.st.s * yPy;
    return num / (mo.Np * D);
  };
  run.em = run_em(X, run.TY, opt, mstep, [] { return 0.0; });
  return run;
}

MatrixXd rotation_2d(double a) {
  MatrixXd R(2, 2);
  R << std::cos(a), -std::sin(a), std::sin(a), std::cos(a);
  return R;
}

// Candidate initial rotations from second moments (normalised, zero-mean sets).
std::vector<MatrixXd> moment_candidates(const MatrixXd& X, const MatrixXd& Y) {
  const int D = static_cast<int>(X.cols());
  auto axes = [](const MatrixXd& P) {
    const MatrixXd C = P.transpose() * P / static_cast<double>(P.rows());
    Eigen::SelfAdjointEigenSolver<MatrixXd> es(C);
    return MatrixXd(es.eigenvectors().rowwise().reverse());  // descending eigenvalues
  };
  const MatrixXd EX = axes(X), EY = axes(Y);
  std::vector<MatrixXd> out;
  const double dsign = EX.determinant() * EY.determinant() < 0.0 ? -1.0 : 1.0;
  if (D == 2) {
    MatrixXd F = MatrixXd::Identity(2, 2);
    F(1, 1) = dsign;
    for (int k = 0; k < 4; ++k) out.push_back(EX * rotation_2d(k * std::numbers::pi / 2) * F * EY.transpose());
  } else {
    for (int mask = 0; mask < 8; ++mask) {
      VectorXd S(3);
      for (int d = 0; d < 3; ++d) S(d) = (mask >> d) & 1 ? -1.0 : 1.0;
      const MatrixXd R = EX * S.asDiagonal() * EY.transpose();
      if (R.determinant() > 0.0) out.push_back(R);
    }
  }
  return out;
}

// Rigid stage in normalised coordinates, with the optional moment-based candidates.
RigidRun rigid_stage(const MatrixXd& X, const MatrixXd& Y, const CpdOptions& opt, int* candidate) {
  const int D = static_cast<int>(X.cols());
  RigidState id{MatrixXd::Identity(D, D), 1.0, VectorXd::Zero(D)};
  if (opt.prealign != CpdPrealign::kMoments) {
    *candidate = -1;
    return run_rigid(X, Y, opt, id);
  }
  const std::vector<MatrixXd> cands = moment_candidates(X, Y);
  RigidRun best;
  for (size_t i = 0; i < cands.size(); ++i) {
    RigidState init = id;
    init.R = cands[i];
    RigidRun r = run_rigid(X, Y, opt, init);
    if (i == 0 || r.em.nll < best.em.nll) {
      best = std::move(r);
      *candidate = static_cast<int>(i);
    }
  }
  return best;
}

// Diagonally pivoted incomplete Cholesky of the Gaussian kernel matrix of Y (width beta):
// G ~ L L^T, L = G(:, piv) G(piv, piv)^-1/2-like (Nystrom at the pivots).
struct LowRankKernel {
  MatrixXd L;               // M x r
  std::vector<int> pivots;  // r
  double error_bound = 0.0;  // max residual diagonal
};

LowRankKernel pivoted_cholesky(const MatrixXd& Y, double beta, double tol, int max_rank) {
  const Index M = Y.rows();
  const double inv2b2 = 1.0 / (2.0 * beta * beta);
  VectorXd diag = VectorXd::Ones(M);
  std::vector<VectorXd> cols;
  LowRankKernel k;
  const Index rmax = std::min<Index>(max_rank, M);
  for (Index j = 0; j < rmax; ++j) {
    Index p = 0;
    const double dmax = diag.maxCoeff(&p);  // first index of the maximum (deterministic)
    if (dmax < tol) break;
    VectorXd col(M);
    const Eigen::RowVectorXd yp = Y.row(p);
#pragma omp parallel for schedule(static) if (M > 20000)
    for (Index i = 0; i < M; ++i) col(i) = std::exp(-(Y.row(i) - yp).squaredNorm() * inv2b2);
    for (Index i = 0; i < j; ++i) col -= cols[static_cast<size_t>(i)](p) * cols[static_cast<size_t>(i)];
    col /= std::sqrt(dmax);
    diag -= col.cwiseAbs2();
    diag = diag.cwiseMax(0.0);
    diag(p) = 0.0;
    cols.push_back(std::move(col));
    k.pivots.push_back(static_cast<int>(p));
  }
  k.error_bound = diag.size() ? diag.maxCoeff() : 0.0;
  k.L.resize(M, static_cast<Index>(cols.size()));
  for (size_t i = 0; i < cols.size(); ++i) k.L.col(static_cast<Index>(i)) = cols[i];
  return k;
}

MatrixXd gaussian_kernel(const MatrixXd& A, const MatrixXd& B, double beta) {
  const double inv2b2 = 1.0 / (2.0 * beta * beta);
  MatrixXd G(A.rows(), B.rows());
#pragma omp parallel for schedule(static) if (A.rows() * B.rows() > 20000)
  for (Index i = 0; i < A.rows(); ++i)
    for (Index j = 0; j < B.rows(); ++j) G(i, j) = std::exp(-(A.row(i) - B.row(j)).squaredNorm() * inv2b2);
  return G;
}

void validate(const MatrixXd& X, const MatrixXd& Y, const CpdOptions& o) {
  auto fail = [](const std::string& what) { throw common::InputError("cpd_register: " + what); };
  if (X.cols() != 2 && X.cols() != 3) fail("expected fixed points with 2 or 3 columns, found " + std::to_string(X.cols()));
  if (Y.cols() != X.cols())
    fail("expected moving points with " + std::to_string(X.cols()) + " columns (as the fixed set), found " +
         std::to_string(Y.cols()));
  if (X.rows() < 1 || Y.rows() < 1) fail("expected non-empty point sets, found " + std::to_string(X.rows()) +
                                         " fixed and " + std::to_string(Y.rows()) + " moving points");
  for (Index i = 0; i < X.rows(); ++i)
    if (!X.row(i).allFinite()) fail("fixed point " + std::to_string(i) + " is not finite");
  for (Index i = 0; i < Y.rows(); ++i)
    if (!Y.row(i).allFinite()) fail("moving point " + std::to_string(i) + " is not finite");
  if (!(o.w >= 0.0 && o.w < 1.0)) fail("expected outlier weight w in [0, 1), found " + std::to_string(o.w));
  if (o.max_iterations < 1) fail("expected max_iterations >= 1, found " + std::to_string(o.max_iterations));
  if (!(o.tolerance > 0.0)) fail("expected tolerance > 0, found " + std::to_string(o.tolerance));
  if (!(o.sigma2_floor >= 0.0)) fail("expected sigma2_floor >= 0, found " + std::to_string(o.sigma2_floor));
  if (!(o.beta > 0.0)) fail("expected beta > 0, found " + std::to_string(o.beta));
  if (!(o.lambda > 0.0)) fail("expected lambda > 0, found " + std::to_string(o.lambda));
  if (!(o.bins_per_sigma >= 0.0)) fail("expected bins_per_sigma >= 0, found " + std::to_string(o.bins_per_sigma));
  if (!(o.truncation_sigmas >= 1.0))
    fail("expected truncation_sigmas >= 1, found " + std::to_string(o.truncation_sigmas));
  if (!(o.low_rank_tolerance > 0.0))
    fail("expected low_rank_tolerance > 0, found " + std::to_string(o.low_rank_tolerance));
  if (o.low_rank_max_rank < 1) fail("expected low_rank_max_rank >= 1, found " + std::to_string(o.low_rank_max_rank));
}

}  // namespace

CpdResult cpd_register(const MatrixXd& X_in, const MatrixXd& Y_in, const CpdOptions& opt) {
  validate(X_in, Y_in, opt);
  const int D = static_cast<int>(X_in.cols());
  const Index M = Y_in.rows();
  Normalization nx = compute_normalization(X_in, opt.normalize);
  Normalization ny = compute_normalization(Y_in, opt.normalize);
  if (opt.normalize && (!(nx.scale > 0.0) || !(ny.scale > 0.0)))
    throw common::InputError("cpd_register: a point set has zero spread (all points coincide); cannot normalise (RMS radius "
                     "fixed " + std::to_string(nx.scale) + ", moving " + std::to_string(ny.scale) + ")");
  // Fixed-scale rigid: both sets share X's scale so the fitted scale is exactly 1.
  if (opt.normalize && opt.method == CpdMethod::kRigid && !opt.estimate_scale) ny.scale = nx.scale;
  const MatrixXd X = (X_in.rowwise() - nx.mean) / nx.scale;
  const MatrixXd Y = (Y_in.rowwise() - ny.mean) / ny.scale;

  CpdResult res;
  res.method = opt.method;
  // Data map of a normalised similarity/affine u -> B u + t: y -> sx (B (y - my)/sy + t) + mx.
  auto to_data_linear = [&](const MatrixXd& B, const VectorXd& t, MatrixXd& A_out, VectorXd& b_out) {
    A_out = (nx.scale / ny.scale) * B;
    b_out = nx.scale * t + nx.mean.transpose() - A_out * ny.mean.transpose();
  };

  const bool need_rigid = opt.method == CpdMethod::kRigid || opt.prealign != CpdPrealign::kNone;
  RigidState pre{MatrixXd::Identity(D, D), 1.0, VectorXd::Zero(D)};
  CpdOptions stage2 = opt;
  if (need_rigid) {
    CpdOptions ro = opt;
    if (opt.method != CpdMethod::kRigid) ro.estimate_scale = true;
    RigidRun rr = rigid_stage(X, Y, ro, &res.prealign_candidate);
    pre = rr.st;
    // The next stage starts from the pre-alignment's final sigma2 (its residual misfit) rather
    // than the from-scratch value: a large restart sigma2 would first blur the aligned sets
    // (the non-rigid GMM contracts towards the centroid) and can end in another optimum.
    if (opt.method != CpdMethod::kRigid && opt.sigma2_initial <= 0.0) stage2.sigma2_initial =
        std::max(rr.em.sigma2, std::max(opt.sigma2_floor, std::numeric_limits<double>::min()));
    if (opt.method == CpdMethod::kRigid) {
      copy_em_outcome(rr.em, res);
    }
  }
  {
    MatrixXd A;
    VectorXd b;
    to_data_linear(pre.s * pre.R, pre.t, A, b);
    res.rotation = pre.R;
    res.scale = nx.scale / ny.scale * pre.s;
    res.translation = b;
    res.affine = A;
    res.transform.A = A;
    res.transform.b = b;
    res.transform.out_offset = VectorXd::Zero(D);
  }

  if (opt.method == CpdMethod::kAffine) {
    MatrixXd B = pre.s * pre.R;
    VectorXd t = pre.t;
    MatrixXd TY = (Y * B.transpose()).rowwise() + t.transpose();
    auto mstep = [&](const EStep& e, MatrixXd& TYo, double) {
      const Moments mo = moments(e, X, Y);
      const MatrixXd Yh = Y.rowwise() - mo.mu_y;
      const MatrixXd YPY = Yh.transpose() * e.P1.asDiagonal() * Yh;
      B = YPY.transpose().ldlt().solve(mo.A.transpose()).transpose();  // B = A YPY^-1 (YPY symmetric)
      t = mo.mu_x.transpose() - B * mo.mu_y.transpose();
      TYo = (Y * B.transpose()).rowwise() + t.transpose();
      return (mo.xPx - (mo.A * B.transpose()).trace()) / (mo.Np * D);
    };
    const EmOutcome em = run_em(X, TY, stage2, mstep, [] { return 0.0; });
    copy_em_outcome(em, res);
    to_data_linear(B, t, res.affine, res.translation);
    res.transform.A = res.affine;
    res.transform.b = res.translation;
    res.rotation = MatrixXd::Identity(D, D);
    res.scale = 1.0;
  } else if (opt.method == CpdMethod::kNonrigid) {
    // Non-rigid on the (pre-aligned) normalised centroids Y0 = s R Y + t.
    const MatrixXd Y0 = ((Y * pre.R.transpose()) * pre.s).rowwise() + pre.t.transpose();
    const bool full = opt.kernel == CpdKernel::kFull ||
                      (opt.kernel == CpdKernel::kAuto && M <= opt.full_kernel_max_points);
    MatrixXd G;
    LowRankKernel lr;
    if (full) {
      G = gaussian_kernel(Y0, Y0, opt.beta);
      res.kernel_rank = static_cast<int>(M);
    } else {
      lr = pivoted_cholesky(Y0, opt.beta, opt.low_rank_tolerance, opt.low_rank_max_rank);
      res.kernel_rank = static_cast<int>(lr.L.cols());
      res.kernel_error_bound = lr.error_bound;
    }
    MatrixXd W = MatrixXd::Zero(M, D);
    MatrixXd TY = Y0;
    double reg = 0.0;
    auto mstep = [&](const EStep& e, MatrixXd& TYo, double sigma2) {
      const double c = opt.lambda * sigma2;
      const MatrixXd F = e.PX - e.P1.asDiagonal() * Y0;
      MatrixXd GW;
      if (full) {
        const SerialEigenScope serial;
        MatrixXd Asys = e.P1.asDiagonal() * G;
        Asys.diagonal().array() += c;
        W = Asys.partialPivLu().solve(F);
        GW = G * W;
        reg = 0.5 * opt.lambda * (W.transpose() * GW).trace();
      } else {
        // Woodbury: (d(P1) L L^T + c I)^-1 F = (F - d(P1) L (c I + L^T d(P1) L)^-1 L^T F) / c.
        const MatrixXd& L = lr.L;
        const MatrixXd DL = e.P1.asDiagonal() * L;
        MatrixXd S = atb_fixed(L, DL);
        S.diagonal().array() += c;
        const MatrixXd LtF = atb_fixed(L, F);
        W = (F - ab_fixed(DL, S.llt().solve(LtF))) / c;
        const MatrixXd LtW = atb_fixed(L, W);
        GW = ab_fixed(L, LtW);
        reg = 0.5 * opt.lambda * LtW.squaredNorm();
      }
      TYo = Y0 + GW;
      const double Np = e.P1.sum();
      const double num = e.Pt1.dot(X.rowwise().squaredNorm()) - 2.0 * (e.PX.cwiseProduct(TYo)).sum() +
                         e.P1.dot(TYo.rowwise().squaredNorm());
      return num / (Np * D);
    };
    const EmOutcome em = run_em(X, TY, stage2, mstep, [&] { return reg; });
    copy_em_outcome(em, res);
    // Transform: u = s R (y - my)/sy + t, T = sx (u + sum_k g(u, c_k) w_k) + mx.
    res.transform.A = (pre.s / ny.scale) * pre.R;
    res.transform.b = pre.t - res.transform.A * ny.mean.transpose();
    res.transform.beta = opt.beta;
    res.transform.out_scale = nx.scale;
    res.transform.out_offset = nx.mean.transpose();
    if (full) {
      res.transform.centres = Y0;
      res.transform.weights = W;
    } else {
      // G~ W = L (L^T W) = G(Y, piv) L_piv^-T (L^T W): an RBF field centred at the pivots.
      const Index r = lr.L.cols();
      MatrixXd Lp(r, r);
      MatrixXd Cp(r, D);
      for (Index j = 0; j < r; ++j) {
        Lp.row(j) = lr.L.row(lr.pivots[static_cast<size_t>(j)]);
        Cp.row(j) = Y0.row(lr.pivots[static_cast<size_t>(j)]);
      }
      const MatrixXd LtW = atb_fixed(lr.L, W);
      res.transform.centres = Cp;
      res.transform.weights = Lp.triangularView<Eigen::Lower>().transpose().solve(LtW);
    }
  }
  res.sigma2_data = res.sigma2 * nx.scale * nx.scale;
  res.transformed = res.transform.apply(Y_in);
  if (!res.transformed.allFinite())
    throw common::NumericalError("cpd_register: the final transformed points are not finite");
  return res;
}

}  // namespace arthrosim::pipelines
