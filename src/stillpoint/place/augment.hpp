#pragma once
// Photometric and small geometric augmentation of training images (torch-free, OpenCV only).
// Deterministic: the random draws depend only on an AugmentKey (seed, epoch, the query's position in
// the epoch, the image's slot in its triplet), never on a rank-local stream, so every rank of a
// data-parallel run and every rerun augments a given image identically.
#include <cstdint>
#include <opencv2/core.hpp>

namespace sp::place {

struct AugmentOptions {
  bool enabled = true;            // off: augment_image returns the input unchanged
  double brightness = 0.25;       // gain uniform in [1 − b, 1 + b]
  double contrast = 0.25;         // blend with the mean grey level: factor in [1 − c, 1 + c]
  double saturation = 0.3;        // blend with each pixel's grey level: factor in [1 − s, 1 + s]
  double gamma = 0.35;            // exposure curve x^γ, ln γ uniform in [−g, g] (γ ≈ 0.70 … 1.42)
  double blur_probability = 0.3;  // chance of a Gaussian blur
  double blur_sigma_max = 1.5;    // px; σ uniform in [0.3, max] when blurred
  double noise_sigma_max = 8.0;   // grey levels of 255; σ uniform in [0, max]
  double crop_max = 0.1;          // each side loses a fraction uniform in [0, max], then resized back
};

// Throws sp::Error for a negative range, a probability outside [0, 1] or crop_max outside [0, 0.3]
// (more would change which place the image shows).
void validate(const AugmentOptions& o);

// Which image of which triplet: slot 0 = query, 1 = positive, 2 + k = the k-th negative.
struct AugmentKey {
  std::uint64_t seed = 0;
  int epoch = 0;
  std::int64_t query = 0;  // position of the query in the epoch's order (the same on every rank)
  int slot = 0;
};

// 8-bit 3-channel image (RGB or BGR; only the grey weights assume RGB) → augmented image of the same
// size and type. Order: crop and resize back, brightness, contrast, saturation, gamma, blur, noise.
[[nodiscard]] cv::Mat augment_image(const cv::Mat& image, const AugmentOptions& o, const AugmentKey& key);

}  // namespace sp::place
