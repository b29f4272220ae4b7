// libFuzzer target: the binary vocabulary file (loop/vocabulary). Two modes, chosen by the first byte:
//  even: the rest is the file as is (magic, header, size and checksum checks);
//  odd:  bytes 1..2 are k and levels, 3..4 the word count, the rest the node records; the harness
//        writes a well-formed header and a correct checksum around them, so the fuzzer reaches the
//        structural checks and the tree descent behind the checksum.
// A vocabulary that loads must describe every descriptor by a valid word.
#include <cstdlib>
#include <cstring>
#include <opencv2/core.hpp>
#include <vector>

#include "fuzz_util.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/loop/vocabulary.hpp"

namespace {

std::uint64_t fnv1a64(const char* data, std::size_t n) {
  std::uint64_t h = 14695981039346656037ULL;
  for (std::size_t i = 0; i < n; ++i) {
    h ^= static_cast<std::uint8_t>(data[i]);
    h *= 1099511628211ULL;
  }
  return h;
}

template <typename T>
void put(std::vector<char>& buf, T v) {
  const auto* p = reinterpret_cast<const char*>(&v);
  buf.insert(buf.end(), p, p + sizeof(T));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const auto file = sp::fuzz::scratch_file("vocab.spv");
  if (size < 1) return 0;
  if ((data[0] & 1U) == 0) {
    sp::fuzz::write_file(file, data + 1, size - 1);
  } else {
    if (size < 5) return 0;
    const std::uint32_t k = data[1] % 40;
    const std::uint32_t levels = data[2] % 10;
    const std::uint32_t words = data[3] | (std::uint32_t{data[4]} << 8U);
    const std::size_t body = size - 5;
    const std::uint32_t n = static_cast<std::uint32_t>(body / 40);
    std::vector<char> buf = {'S', 'P', 'V', 'O', 'C', 'A', 'B', '1'};
    put<std::uint32_t>(buf, 1);
    put(buf, k);
    put(buf, levels);
    put(buf, n);
    put(buf, words);
    buf.insert(buf.end(), reinterpret_cast<const char*>(data + 5),
               reinterpret_cast<const char*>(data + 5) + std::size_t{n} * 40);
    put(buf, fnv1a64(buf.data(), buf.size()));
    sp::fuzz::write_file(file, buf.data(), buf.size());
  }
  sp::loop::Vocabulary v;
  try {
    v = sp::loop::Vocabulary::load(file);
  } catch (const sp::Error&) {
    return 0;
  }
  // Descend with descriptors taken from the input.
  cv::Mat desc(4, sp::loop::kDescriptorBytes, CV_8UC1, cv::Scalar(0));
  for (int i = 0; i < desc.rows * desc.cols; ++i)
    desc.data[i] = data[(static_cast<std::size_t>(i) * 7) % size];
  if (!v.empty()) {
    for (int r = 0; r < desc.rows; ++r) {
      if (v.word_of(desc.ptr<std::uint8_t>(r)) >= v.size()) std::abort();
    }
    sp::loop::BowVector bow;
    sp::loop::FeatureVector fv;
    v.transform(desc, bow, fv, 2);
  }
  return 0;
}
