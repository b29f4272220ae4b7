#include "stillpoint/place/descriptor.hpp"

#include <ATen/Parallel.h>

#include <opencv2/imgproc.hpp>

#include "stillpoint/common/error.hpp"
#include "stillpoint/place/model.hpp"

namespace sp::place {

struct PlaceDescriptorExtractor::Impl {
  ParCNetVLAD model{nullptr};
};

PlaceDescriptorExtractor::PlaceDescriptorExtractor(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
PlaceDescriptorExtractor::PlaceDescriptorExtractor(PlaceDescriptorExtractor&&) noexcept = default;
PlaceDescriptorExtractor& PlaceDescriptorExtractor::operator=(PlaceDescriptorExtractor&&) noexcept = default;
PlaceDescriptorExtractor::~PlaceDescriptorExtractor() = default;

PlaceDescriptorExtractor PlaceDescriptorExtractor::load(const std::filesystem::path& model_file,
                                                        int threads) {
  if (threads > 0) at::set_num_threads(threads);
  auto impl = std::make_unique<Impl>();
  impl->model = load_model(model_file);
  impl->model->eval();
  return PlaceDescriptorExtractor(std::move(impl));
}

static cv::Mat as_bgr(const cv::Mat& image) {
  if (image.empty()) throw sp::Error("PlaceDescriptorExtractor: empty image");
  if (image.type() == CV_8UC3) return image;
  cv::Mat bgr;
  if (image.type() == CV_8UC1) {
    cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
  } else if (image.type() == CV_8UC4) {
    cv::cvtColor(image, bgr, cv::COLOR_BGRA2BGR);
  } else {
    throw sp::Error("PlaceDescriptorExtractor: expected an 8-bit grey, BGR or BGRA image");
  }
  return bgr;
}

Eigen::MatrixXf PlaceDescriptorExtractor::describe_batch(const std::vector<cv::Mat>& images) {
  const int dim = dimension();
  Eigen::MatrixXf out(static_cast<Eigen::Index>(images.size()), dim);
  if (images.empty()) return out;
  const auto& cfg = impl_->model->cfg;
  std::vector<torch::Tensor> batch;
  batch.reserve(images.size());
  for (const auto& im : images)
    batch.push_back(image_to_tensor(as_bgr(im), cfg.input_height, cfg.input_width));
  torch::NoGradGuard guard;
  const auto d = impl_->model->forward(torch::cat(batch, 0)).contiguous();
  // Eigen is column-major: copy each row.
  const float* p = d.data_ptr<float>();
  for (Eigen::Index i = 0; i < out.rows(); ++i) {
    out.row(i) = Eigen::Map<const Eigen::RowVectorXf>(p + i * dim, dim);
  }
  return out;
}

Eigen::VectorXf PlaceDescriptorExtractor::describe(const cv::Mat& bgr) {
  return describe_batch({bgr}).row(0).transpose();
}

int PlaceDescriptorExtractor::dimension() const { return impl_->model->cfg.descriptor_dim(); }
int PlaceDescriptorExtractor::input_width() const { return impl_->model->cfg.input_width; }
int PlaceDescriptorExtractor::input_height() const { return impl_->model->cfg.input_height; }

}  // namespace sp::place
