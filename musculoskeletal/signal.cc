#include "musculoskeletal/signal.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <sstream>
#include <stdexcept>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

std::vector<Biquad> butterworth_lowpass(double cutoff_hz, double rate_hz, int order) {
  if (order < 2 || order > 8 || order % 2 != 0) {
    throw std::invalid_argument("butterworth_lowpass: order must be even in 2..8, found " +
                                std::to_string(order));
  }
  if (!(rate_hz > 0) || !(cutoff_hz > 0) || !(cutoff_hz < 0.5 * rate_hz)) {
    std::ostringstream s;
    s << "butterworth_lowpass: need 0 < cutoff < rate/2, found cutoff " << cutoff_hz
      << " Hz at rate " << rate_hz << " Hz";
    throw std::invalid_argument(s.str());
  }
  // Pre-warped bilinear transform of each analog section 1 / (s^2 + s/Q + 1),
  // with s = (1/K)(1 - z^-1)/(1 + z^-1), K = tan(pi fc / fs).
  const double K = std::tan(M_PI * cutoff_hz / rate_hz);
  std::vector<Biquad> sections;
  for (int k = 1; k <= order / 2; ++k) {
    const double Q = 1.0 / (2.0 * std::cos((2.0 * k - 1.0) * M_PI / (2.0 * order)));
    const double norm = 1.0 / (1.0 + K / Q + K * K);
    Biquad b;
    b.b0 = K * K * norm;
    b.b1 = 2.0 * b.b0;
    b.b2 = b.b0;
    b.a1 = 2.0 * (K * K - 1.0) * norm;
    b.a2 = (1.0 - K / Q + K * K) * norm;
    sections.push_back(b);
  }
  return sections;
}

Eigen::VectorXd filter_forward(const std::vector<Biquad>& sections, const Eigen::VectorXd& x,
                               bool steady_state_start) {
  Eigen::VectorXd y = x;
  for (const Biquad& s : sections) {
    double z1 = 0.0, z2 = 0.0;
    if (steady_state_start && y.size() > 0) {
      // At rest for a constant input c (unity DC gain, output c):
      // z2 = (b2 - a2) c, z1 = c - b0 c.
      const double c = y(0);
      z2 = (s.b2 - s.a2) * c;
      z1 = (1.0 - s.b0) * c;
    }
    for (Eigen::Index i = 0; i < y.size(); ++i) {
      const double xi = y(i);
      const double yi = s.b0 * xi + z1;
      z1 = s.b1 * xi - s.a1 * yi + z2;
      z2 = s.b2 * xi - s.a2 * yi;
      y(i) = yi;
    }
  }
  return y;
}

double gain(const std::vector<Biquad>& sections, double f_hz, double rate_hz) {
  const std::complex<double> z1 = std::polar(1.0, -2.0 * M_PI * f_hz / rate_hz);  // z^-1
  std::complex<double> h = 1.0;
  for (const Biquad& s : sections) {
    h *= (s.b0 + s.b1 * z1 + s.b2 * z1 * z1) / (1.0 + s.a1 * z1 + s.a2 * z1 * z1);
  }
  return std::abs(h);
}

namespace {

// Odd reflection about both end values.
Eigen::VectorXd pad_odd(const Eigen::VectorXd& x, int pad) {
  const Eigen::Index n = x.size();
  Eigen::VectorXd out(n + 2 * pad);
  for (int k = 1; k <= pad; ++k) {
    out(pad - k) = 2.0 * x(0) - x(k);
    out(pad + n - 1 + k) = 2.0 * x(n - 1) - x(n - 1 - k);
  }
  out.segment(pad, n) = x;
  return out;
}

// Periodic continuation with drift: the samples 0..n-2 are one period, the
// last sample repeats the first plus the drift.
Eigen::VectorXd pad_periodic(const Eigen::VectorXd& x, int pad) {
  const Eigen::Index n = x.size(), period = n - 1;
  const double drift = x(n - 1) - x(0);
  auto value = [&](Eigen::Index i) {  // any integer i
    Eigen::Index q = i >= 0 ? i / period : -((-i + period - 1) / period);
    const Eigen::Index r = i - q * period;
    return x(r) + static_cast<double>(q) * drift;
  };
  Eigen::VectorXd out(n + 2 * pad);
  for (Eigen::Index i = 0; i < out.size(); ++i) out(i) = value(i - pad);
  return out;
}

}  // namespace

Eigen::MatrixXd filtfilt_lowpass(const Eigen::MatrixXd& x, double rate_hz,
                                 const LowPassOptions& options, const std::string& what) {
  const Eigen::Index n = x.rows();
  if (n < 4) {
    throw common::InputError(what + ": error: the low-pass needs at least 4 samples, found " +
                             std::to_string(n));
  }
  const auto sections = butterworth_lowpass(options.cutoff_hz, rate_hz, options.pass_order);
  int pad = options.pad_samples;
  if (pad < 0) {
    pad = static_cast<int>(std::ceil((options.periodic ? 4.0 : 2.0) * rate_hz / options.cutoff_hz));
  }
  if (!options.periodic) pad = std::min<int>(pad, static_cast<int>(n - 1));
  Eigen::MatrixXd out(n, x.cols());
  for (Eigen::Index c = 0; c < x.cols(); ++c) {
    Eigen::VectorXd p = options.periodic ? pad_periodic(x.col(c), pad) : pad_odd(x.col(c), pad);
    p = filter_forward(sections, p, true);
    p.reverseInPlace();
    p = filter_forward(sections, p, true);
    p.reverseInPlace();
    out.col(c) = p.segment(pad, n);
  }
  return out;
}

Eigen::VectorXd uniform_grid(double t_begin, double t_end, double rate_hz) {
  if (!(rate_hz > 0) || !(t_end >= t_begin)) {
    std::ostringstream s;
    s << "uniform_grid: need rate > 0 and t_end >= t_begin, found rate " << rate_hz << " Hz, ["
      << t_begin << ", " << t_end << "] s";
    throw std::invalid_argument(s.str());
  }
  const double h = 1.0 / rate_hz;
  const auto count = static_cast<Eigen::Index>(std::floor((t_end - t_begin) / h + 1e-9 / h)) + 1;
  Eigen::VectorXd t(count);
  for (Eigen::Index i = 0; i < count; ++i) t(i) = t_begin + static_cast<double>(i) * h;
  return t;
}

Eigen::MatrixXd resample_linear(const Eigen::VectorXd& times, const Eigen::MatrixXd& values,
                                const Eigen::VectorXd& new_times, const std::string& what) {
  const Eigen::Index n = times.size();
  if (n < 2 || values.rows() != n) {
    throw common::InputError(what + ": error: resampling needs at least 2 samples and one time "
                             "per row, found " + std::to_string(n) + " times and " +
                             std::to_string(values.rows()) + " rows");
  }
  for (Eigen::Index i = 1; i < n; ++i) {
    if (!(times(i) > times(i - 1))) {
      std::ostringstream s;
      s << what << ": error: time must increase strictly, found " << times(i - 1) << " s then "
        << times(i) << " s at rows " << i - 1 << " and " << i << " (0-based data rows)";
      throw common::InputError(s.str());
    }
  }
  constexpr double kTol = 1e-9;
  Eigen::MatrixXd out(new_times.size(), values.cols());
  Eigen::Index j = 0;  // interval [times(j), times(j+1)]
  for (Eigen::Index i = 0; i < new_times.size(); ++i) {
    const double t = new_times(i);
    if (t < times(0) - kTol || t > times(n - 1) + kTol) {
      std::ostringstream s;
      s << what << ": error: requested time " << t << " s outside the data range [" << times(0)
        << ", " << times(n - 1) << "] s";
      throw common::InputError(s.str());
    }
    while (j + 2 < n && times(j + 1) < t) ++j;
    while (j > 0 && times(j) > t) --j;
    const double w = std::clamp((t - times(j)) / (times(j + 1) - times(j)), 0.0, 1.0);
    out.row(i) = (1.0 - w) * values.row(j) + w * values.row(j + 1);
  }
  return out;
}

Eigen::MatrixXd first_derivative(const Eigen::MatrixXd& x, double h, bool periodic) {
  const Eigen::Index n = x.rows();
  if (n < 4) throw std::invalid_argument("first_derivative: need at least 4 samples");
  Eigen::MatrixXd d(n, x.cols());
  for (Eigen::Index i = 1; i + 1 < n; ++i) d.row(i) = (x.row(i + 1) - x.row(i - 1)) / (2.0 * h);
  if (periodic) {
    // x[-1] = x[n-2] - drift, x[n] = x[1] + drift; both ends see the same neighbours.
    const Eigen::RowVectorXd drift = x.row(n - 1) - x.row(0);
    d.row(0) = (x.row(1) - (x.row(n - 2) - drift)) / (2.0 * h);
    d.row(n - 1) = d.row(0);
  } else {
    d.row(0) = (-3.0 * x.row(0) + 4.0 * x.row(1) - x.row(2)) / (2.0 * h);
    d.row(n - 1) = (3.0 * x.row(n - 1) - 4.0 * x.row(n - 2) + x.row(n - 3)) / (2.0 * h);
  }
  return d;
}

Eigen::MatrixXd second_derivative(const Eigen::MatrixXd& x, double h, bool periodic) {
  const Eigen::Index n = x.rows();
  if (n < 4) throw std::invalid_argument("second_derivative: need at least 4 samples");
  Eigen::MatrixXd d(n, x.cols());
  const double h2 = h * h;
  for (Eigen::Index i = 1; i + 1 < n; ++i)
    d.row(i) = (x.row(i + 1) - 2.0 * x.row(i) + x.row(i - 1)) / h2;
  if (periodic) {
    const Eigen::RowVectorXd drift = x.row(n - 1) - x.row(0);
    d.row(0) = (x.row(1) - 2.0 * x.row(0) + (x.row(n - 2) - drift)) / h2;
    d.row(n - 1) = d.row(0);
  } else {
    d.row(0) = (2.0 * x.row(0) - 5.0 * x.row(1) + 4.0 * x.row(2) - x.row(3)) / h2;
    d.row(n - 1) = (2.0 * x.row(n - 1) - 5.0 * x.row(n - 2) + 4.0 * x.row(n - 3) - x.row(n - 4)) / h2;
  }
  return d;
}

}  // namespace arthrosim::musculoskeletal
