#include "stillpoint/features/orb_pattern.hpp"

namespace sp::feat {
namespace {

// splitmix64: tiny, well-mixed, and fully specified by integer arithmetic.
class SplitMix64 {
 public:
  explicit SplitMix64(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() {
    std::uint64_t z = (state_ += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }

 private:
  std::uint64_t state_;
};

// Approximately N(0, sigma^2) rounded to an integer, using only integer arithmetic: the sum of 12
// uniforms on [0, 1) has variance 1 (Irwin-Hall), so no libm function can change the pattern.
int gaussian_int(SplitMix64& rng, int sigma_num, int sigma_den) {
  constexpr std::int64_t kOne = 1 << 16;
  std::int64_t sum = 0;
  for (int i = 0; i < 12; ++i) sum += static_cast<std::int64_t>(rng.next() >> 48);
  const std::int64_t centred = (sum - 6 * kOne) * sigma_num;  // in units of 1/(kOne*sigma_den)
  const std::int64_t den = kOne * sigma_den;
  // Round half away from zero.
  return static_cast<int>(centred >= 0 ? (2 * centred + den) / (2 * den)
                                       : -((-2 * centred + den) / (2 * den)));
}

}  // namespace

OrbPattern OrbPattern::generate(std::uint64_t seed) {
  SplitMix64 rng(seed);
  OrbPattern p;
  const auto draw = [&](int& px, int& py) {
    do {
      px = gaussian_int(rng, 31, 5);
      py = gaussian_int(rng, 31, 5);
    } while (px * px + py * py > kRadius * kRadius);
  };
  for (int i = 0; i < kPairs; ++i) {
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    draw(x0, y0);
    do {
      draw(x1, y1);
    } while (x1 == x0 && y1 == y0);  // a test of a pixel against itself carries no information
    p.x[2 * i] = static_cast<std::int8_t>(x0);
    p.y[2 * i] = static_cast<std::int8_t>(y0);
    p.x[2 * i + 1] = static_cast<std::int8_t>(x1);
    p.y[2 * i + 1] = static_cast<std::int8_t>(y1);
  }
  return p;
}

std::uint64_t OrbPattern::fingerprint() const {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  const auto mix = [&](std::int8_t v) {
    h ^= static_cast<std::uint8_t>(v);
    h *= 0x100000001b3ULL;
  };
  for (int i = 0; i < 2 * kPairs; ++i) {
    mix(x[static_cast<std::size_t>(i)]);
    mix(y[static_cast<std::size_t>(i)]);
  }
  return h;
}

}  // namespace sp::feat
