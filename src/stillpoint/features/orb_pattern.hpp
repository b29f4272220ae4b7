#pragma once
// The fixed 256-pair sampling pattern of the rBRIEF descriptor, drawn by our own integer PRNG so that
// it is bit-identical on every platform and standard library. Vocabularies (data/vocab) are trained
// on the descriptors of one pattern: never change the default silently.
#include <array>
#include <cstdint>

namespace sp::feat {

struct OrbPattern {
  static constexpr int kPairs = 256;
  static constexpr int kRadius = 15;  // every point lies in the disc of this radius [px]
  static constexpr std::uint64_t kDefaultSeed = 0x5157494c4c504f49ULL;

  // Pair i compares point (x[2i], y[2i]) with (x[2i+1], y[2i+1]); offsets from the keypoint [px].
  std::array<std::int8_t, 2 * kPairs> x{};
  std::array<std::int8_t, 2 * kPairs> y{};

  // Points ~ isotropic Gaussian with sigma = 31/5 px (BRIEF's G II), restricted to the disc so that
  // steering by any angle keeps them inside the 31x31 patch. Deterministic for a given seed.
  static OrbPattern generate(std::uint64_t seed = kDefaultSeed);
  // 256 tests selected (offline, once, see tests/features/tools/learn_pattern) from the candidates
  // of generate(kDefaultSeed + k), k < 64, for low bias and low correlation, as rBRIEF. Same
  // recall as generate() with ~40 % fewer wrong ratio-test matches; opt-in via OrbConfig::pattern
  // because a vocabulary trained on generate() descriptors does not fit it.
  static OrbPattern decorrelated();
  // FNV-1a hash of the coordinates: a fingerprint to detect an accidental change of the pattern.
  [[nodiscard]] std::uint64_t fingerprint() const;
};

}  // namespace sp::feat
