#pragma once
// Error types. User input problems throw InputError whose message reads
// "<file>:<line>: error: <what was expected>, found <what was found>" (line
// omitted when unknown; for HDF5 the "line" is the dataset path). Numerical
// failures throw NumericalError naming where they happened. Internal
// invariants use assert/abort, not exceptions.
#include <stdexcept>
#include <string>

namespace arthrosim::common {

class InputError : public std::runtime_error {
 public:
  InputError(const std::string& file, int line, const std::string& message)
      : std::runtime_error(format(file, line, 0, message)), file_(file), line_(line) {}
  /// With a column (1-based) as well: "<file>:<line>:<column>: error: ...".
  InputError(const std::string& file, int line, int column, const std::string& message)
      : std::runtime_error(format(file, line, column, message)),
        file_(file),
        line_(line),
        column_(column) {}
  explicit InputError(const std::string& message) : std::runtime_error(message), line_(0) {}
  const std::string& file() const { return file_; }
  int line() const { return line_; }
  int column() const { return column_; }

 private:
  static std::string format(const std::string& file, int line, int column,
                            const std::string& message) {
    std::string s = file;
    if (line > 0) s += ":" + std::to_string(line);
    if (line > 0 && column > 0) s += ":" + std::to_string(column);
    return s + ": error: " + message;
  }
  std::string file_;
  int line_;
  int column_ = 0;
};

/// NaN/Inf, a solver that did not converge where that is fatal, etc.
class NumericalError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace arthrosim::common
