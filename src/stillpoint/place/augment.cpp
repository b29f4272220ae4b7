#include "stillpoint/place/augment.hpp"

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>

#include "stillpoint/common/error.hpp"

namespace sp::place {

void validate(const AugmentOptions& o) {
  const auto in = [](double v, double lo, double hi, const char* what) {
    if (!(v >= lo && v <= hi))
      throw sp::Error(std::string("augmentation: ") + what + " must be in [" + std::to_string(lo) + ", " +
                      std::to_string(hi) + "], not " + std::to_string(v));
  };
  in(o.brightness, 0, 0.9, "brightness");
  in(o.contrast, 0, 0.9, "contrast");
  in(o.saturation, 0, 1, "saturation");
  in(o.gamma, 0, 1.5, "gamma");
  in(o.blur_probability, 0, 1, "blur probability");
  in(o.blur_sigma_max, 0.3, 10, "blur sigma");
  in(o.noise_sigma_max, 0, 64, "noise sigma");
  in(o.crop_max, 0, 0.3, "crop fraction");
}

cv::Mat augment_image(const cv::Mat& image, const AugmentOptions& o, const AugmentKey& key) {
  if (image.empty() || image.type() != CV_8UC3)
    throw sp::Error("augment_image: expected an 8-bit 3-channel image");
  if (!o.enabled) return image.clone();
  std::seed_seq sseq{static_cast<std::uint32_t>(key.seed),
                     static_cast<std::uint32_t>(key.seed >> 32),
                     static_cast<std::uint32_t>(key.epoch),
                     static_cast<std::uint32_t>(key.query),
                     static_cast<std::uint32_t>(static_cast<std::uint64_t>(key.query) >> 32),
                     static_cast<std::uint32_t>(key.slot),
                     0x41554731u /* "AUG1": apart from mining */};
  std::mt19937_64 rng(sseq);
  // A draw in [0, 1) from the top 53 bits: the same value on every standard library (unlike
  // std::uniform_real_distribution, whose algorithm is unspecified), so ranks built differently agree.
  const auto u = [&rng] { return static_cast<double>(rng() >> 11) * 0x1.0p-53; };
  const auto sym = [&](double r) { return (2 * u() - 1) * r; };

  const int h = image.rows, w = image.cols;
  cv::Mat f;
  // Crop: each side independently, at least 1 px kept in each direction.
  const int left = static_cast<int>(std::floor(u() * o.crop_max * w));
  const int right = static_cast<int>(std::floor(u() * o.crop_max * w));
  const int top = static_cast<int>(std::floor(u() * o.crop_max * h));
  const int bottom = static_cast<int>(std::floor(u() * o.crop_max * h));
  const cv::Rect roi(left, top, std::max(1, w - left - right), std::max(1, h - top - bottom));
  if (roi.width != w || roi.height != h) {
    cv::Mat resized;
    cv::resize(image(roi), resized, image.size(), 0, 0, cv::INTER_LINEAR);
    resized.convertTo(f, CV_32FC3, 1.0 / 255.0);
  } else {
    image.convertTo(f, CV_32FC3, 1.0 / 255.0);
  }
  // Colour jitter in [0, 1] floats; grey = Rec. 601 luma of RGB.
  const double gain = 1 + sym(o.brightness);
  const double contrast = 1 + sym(o.contrast);
  const double saturation = 1 + sym(o.saturation);
  const double gamma = std::exp(sym(o.gamma));
  const bool blur = u() < o.blur_probability;
  const double sigma_blur = 0.3 + u() * (o.blur_sigma_max - 0.3);
  const double sigma_noise = u() * o.noise_sigma_max / 255.0;
  f *= gain;
  cv::Mat grey;
  cv::transform(f, grey, cv::Matx13f(0.299f, 0.587f, 0.114f));
  const double mean_grey = cv::mean(grey)[0];
  f = (f - cv::Scalar::all(mean_grey)) * contrast + cv::Scalar::all(mean_grey);
  grey = (grey - mean_grey) * contrast + mean_grey;
  cv::Mat grey3;
  cv::merge(std::vector<cv::Mat>{grey, grey, grey}, grey3);
  f = grey3 + (f - grey3) * saturation;
  cv::max(f, 0.0, f);
  cv::min(f, 1.0, f);
  cv::pow(f, gamma, f);  // exposure: stands in for lighting, which dynsynth places cannot vary
  if (blur) cv::GaussianBlur(f, f, cv::Size(0, 0), sigma_blur);
  if (sigma_noise > 0) {
    cv::Mat noise(f.size(), f.type());
    cv::RNG crng(rng());
    crng.fill(noise, cv::RNG::NORMAL, cv::Scalar::all(0), cv::Scalar::all(sigma_noise));
    f += noise;
  }
  cv::Mat out;
  f.convertTo(out, CV_8UC3, 255.0);  // saturates to [0, 255]
  return out;
}

}  // namespace sp::place
