#pragma once
// Signal processing for gait trials: resampling, a zero-lag Butterworth
// low-pass (our own implementation) and finite-difference derivatives.
//
// Low-pass. A Butterworth filter of even order N (the order of ONE pass) is
// built as N/2 second-order sections from the analog prototype
//   H(s) = prod_k 1 / (s^2 + s / Q_k + 1),  Q_k = 1 / (2 cos((2k - 1) pi / (2N))),
// mapped to z by the bilinear transform with pre-warping K = tan(pi fc / fs),
// so |H(e^{i 2 pi fc / fs})| = 1/sqrt(2) (-3 dB) exactly at the cutoff fc for a
// single pass. The zero-lag filter (filtfilt) runs the cascade forward, then
// backward over the reversed output: the phase cancels and the magnitude is
// squared, |H|^2 (-6 dB at fc), i.e. a zero-lag filter of order 2N. The default
// N = 2 gives the "4th-order zero-lag Butterworth" of gait analysis
// (Winter 2009, section 3.4); no cutoff correction for the double pass is
// applied (fc is the cutoff of each pass -- say so when quoting it).
//
// End effects: before each pass the signal is extended at both ends by odd
// (point) reflection, x[-k] = 2 x[0] - x[k], which continues value and slope
// (but forces the second derivative towards zero at the two ends: use the
// periodic option for a trial that is exactly one cycle),
// and every section starts in its steady state for the first padded value: a
// constant passes through unchanged, a straight line up to the start transient
// decayed over the padding (~5e-6 x slope[1/s] for the defaults, measured).
//
// Derivatives on a uniform grid of step h: central differences inside,
//   f'_i  = (f_{i+1} - f_{i-1}) / (2h),       f''_i = (f_{i+1} - 2 f_i + f_{i-1}) / h^2,
// and second-order one-sided formulas at the two ends
//   f'_0  = (-3 f_0 + 4 f_1 - f_2) / (2h),    f''_0 = (2 f_0 - 5 f_1 + 4 f_2 - f_3) / h^2
// (mirrored at the last sample). All are O(h^2) accurate (measured in
// tests/musculoskeletal/signal_test.cc).
//
// Resampling: piecewise-linear interpolation in time (exact on linear data;
// it cannot overshoot, which matters for forces that drop to zero at toe-off).
// The low-pass that follows removes the slope kinks it leaves at the original
// samples.
#include <Eigen/Core>
#include <string>
#include <vector>

namespace arthrosim::musculoskeletal {

/// One second-order section, direct form II transposed:
///   y = b0 x + z1,  z1 <- b1 x - a1 y + z2,  z2 <- b2 x - a2 y.
struct Biquad {
  double b0 = 1, b1 = 0, b2 = 0, a1 = 0, a2 = 0;
};

struct LowPassOptions {
  /// Cutoff of each pass [Hz], 0 < cutoff_hz < rate/2. Default 6 Hz (gait).
  double cutoff_hz = 6.0;
  /// Order of one pass, even, 2..8. The zero-lag filter has twice this order.
  int pass_order = 2;
  /// Samples of padding added at each end before each pass; -1 = automatic:
  /// odd reflection min(n - 1, ceil(2 rate / cutoff)) (two cutoff periods),
  /// periodic ceil(4 rate / cutoff).
  int pad_samples = -1;
  /// Periodic signal (e.g. exactly one gait cycle): the last row is one period
  /// after the first, x[n-1] = x[0] + drift (drift = x[n-1] - x[0], e.g. the
  /// stride in pelvis_tx). Pads with the periodic continuation
  /// x[n-1+k] = x[k] + drift, x[-k] = x[n-1-k] - drift instead of the odd
  /// reflection, so the ends are filtered like the middle.
  bool periodic = false;
};

/// Butterworth low-pass sections for sampling rate `rate_hz`. Throws
/// std::invalid_argument with the offending values on a bad order or cutoff.
std::vector<Biquad> butterworth_lowpass(double cutoff_hz, double rate_hz, int order);

/// Single forward pass of the cascade (zero initial state unless
/// `steady_state_start`, then each section starts at rest for the value x[0]).
Eigen::VectorXd filter_forward(const std::vector<Biquad>& sections, const Eigen::VectorXd& x,
                               bool steady_state_start = false);

/// Complex gain magnitude of the cascade at frequency f [Hz].
double gain(const std::vector<Biquad>& sections, double f_hz, double rate_hz);

/// Zero-lag low-pass of every column of `x` (rows = samples at `rate_hz`).
/// Needs at least 4 samples. `what` names the data in error messages.
Eigen::MatrixXd filtfilt_lowpass(const Eigen::MatrixXd& x, double rate_hz,
                                 const LowPassOptions& options, const std::string& what = "signal");

/// Uniform time grid from t_begin in steps of 1/rate_hz up to t_end (the last
/// point is included when it lies within 1e-9 s of the grid).
Eigen::VectorXd uniform_grid(double t_begin, double t_end, double rate_hz);

/// Linear interpolation of the columns of `values` (rows at the strictly
/// increasing `times`) onto `new_times`, which must lie within
/// [times(0), times(end)] (1e-9 s tolerance). `what` names the data in errors.
Eigen::MatrixXd resample_linear(const Eigen::VectorXd& times, const Eigen::MatrixXd& values,
                                const Eigen::VectorXd& new_times, const std::string& what = "signal");

/// First and second derivatives of every column (uniform step h [s], >= 4 rows).
/// `periodic`: central differences at the ends too, with the periodic
/// continuation described in LowPassOptions::periodic.
Eigen::MatrixXd first_derivative(const Eigen::MatrixXd& x, double h, bool periodic = false);
Eigen::MatrixXd second_derivative(const Eigen::MatrixXd& x, double h, bool periodic = false);

}  // namespace arthrosim::musculoskeletal
