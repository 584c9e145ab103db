// libFuzzer target: a walking trial as a user hands it over -- the trial
// description (trial.yaml) and the .mot/.sto files it names -- read by
// musculoskeletal::load_gait_trial (resampling, filtering, derivatives).
//
// Input: the trial.yaml text, optionally followed by files, each introduced
// by a line "@@ NAME" with NAME one of ik.mot, grf.mot, loads.sto; they are
// written next to the trial.yaml in a scratch folder (files not given are
// absent).
#include <sstream>

#include "fuzz_support.h"
#include "musculoskeletal/gait_trial.h"

namespace {

const char* const kFiles[] = {"ik.mot", "grf.mot", "loads.sto"};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arthrosim;
  const std::filesystem::path& dir = fuzz::scratch_dir();
  const std::string input = fuzz::as_string(data, size);
  // Split at "\n@@ NAME\n" lines.
  std::string description;
  std::string* current = &description;
  std::string files[3];
  bool given[3] = {false, false, false};
  std::size_t pos = 0;
  while (pos <= input.size()) {
    std::size_t end = input.find('\n', pos);
    if (end == std::string::npos) end = input.size();
    const std::string line = input.substr(pos, end - pos);
    bool marker = false;
    if (line.rfind("@@ ", 0) == 0) {
      for (int k = 0; k < 3; ++k) {
        if (line.substr(3) == kFiles[k]) {
          current = &files[k];
          current->clear();
          given[k] = marker = true;
        }
      }
    }
    if (!marker) {
      *current += line;
      if (end < input.size()) *current += '\n';
    }
    pos = end + 1;
  }
  for (int k = 0; k < 3; ++k) {
    std::error_code ec;
    std::filesystem::remove(dir / kFiles[k], ec);
    if (given[k]) fuzz::write_file(dir / kFiles[k], files[k]);
  }
  return fuzz::run_reader([&] {
    std::istringstream in(description);
    const musculoskeletal::TrialDescription d =
        musculoskeletal::parse_trial_description(in, (dir / "trial.yaml").string(), dir.string());
    const musculoskeletal::GaitTrial t = musculoskeletal::load_gait_trial(d);
    (void)t.num_samples();
  });
}
