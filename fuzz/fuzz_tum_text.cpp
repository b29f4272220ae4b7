// libFuzzer target: TUM text lists (rgb.txt, depth.txt, associations.txt, groundtruth.txt) and the
// association of two parsed lists. Only sp::Error may escape the parser; parsed lists must be sane.
#include <cstdlib>

#include "fuzz_util.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/io/association.hpp"
#include "stillpoint/io/tum_text.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const auto file = sp::fuzz::scratch_file("list.txt");
  sp::fuzz::write_file(file, data, size);
  for (std::size_t columns : {0U, 2U, 4U, 8U}) {
    try {
      const auto records = sp::io::read_tum_text(file, columns);
      for (std::size_t i = 0; i < records.size(); ++i) {
        if (columns != 0 && records[i].columns.size() != columns) std::abort();
        if (i > 0 && !(records[i].stamp > records[i - 1].stamp)) std::abort();
        if (records[i].line <= 0) std::abort();
      }
    } catch (const sp::Error&) {
    }
  }
  try {
    const auto list = sp::io::read_tum_file_list(file);
    std::vector<double> a, b;
    for (const auto& e : list) {
      a.push_back(e.stamp);
      b.push_back(e.stamp + 0.01);
    }
    const auto pairs = sp::io::associate(a, b, 0.0, 0.02);
    for (const auto& [i, j] : pairs) {
      if (i >= a.size() || j >= b.size()) std::abort();
    }
  } catch (const sp::Error&) {
  }
  return 0;
}
