// libFuzzer target: the split-line map readers of the post stage
// (pipelines::parse_splitline_svg / parse_splitline_csv, docs/post.md): an
// input starting with '<' (after blanks) is read as SVG, anything else as CSV.
#include "fuzz_support.h"
#include "pipelines/splitline.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arthrosim;
  const std::string text = fuzz::as_string(data, size);
  const std::size_t first = text.find_first_not_of(" \t\r\n");
  const bool svg = first != std::string::npos && text[first] == '<';
  return fuzz::run_reader([&] {
    const pipelines::SplitLineMap map =
        svg ? pipelines::parse_splitline_svg(text, "fuzz.svg") : pipelines::parse_splitline_csv(text, "fuzz.csv");
    (void)map.samples.rows();
  });
}
