// libFuzzer target: common::parse_storage (.sto/.mot), then the column and
// unit queries a consumer makes (time, each column by label, the rotational rule).
#include <sstream>

#include "common/storage.h"
#include "fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arthrosim;
  return fuzz::run_reader([&] {
    std::istringstream in(fuzz::as_string(data, size));
    const common::StorageTable t = common::parse_storage(in, "fuzz.sto");
    if (t.num_columns() > 0) (void)t.time();
    for (const auto& label : t.labels) {
      (void)t.column(label);
      (void)common::default_is_rotational(label);
    }
  });
}
