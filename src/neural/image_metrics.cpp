#include "hanzo/fusion/neural/image_metrics.hpp"

#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::neural {

double psnr(const std::vector<float>& image, const std::vector<float>& reference) {
  double sum = 0.0;
  for (std::size_t i = 0; i < image.size(); ++i) {
    const double d = static_cast<double>(image[i]) - static_cast<double>(reference[i]);
    sum += d * d;
  }
  const double mse = sum / static_cast<double>(std::max<std::size_t>(1, image.size()));
  return mse > 0.0 ? 10.0 * std::log10(1.0 / mse) : std::numeric_limits<double>::infinity();
}

namespace {

constexpr double kC1 = 0.01 * 0.01;
constexpr double kC2 = 0.03 * 0.03;

// The window as a separable filter with zero padding (its own transpose: the kernel is symmetric).
cv::Mat window(const cv::Mat& image) {
  static const cv::Mat kernel = cv::getGaussianKernel(11, 1.5, CV_64F);
  cv::Mat out;
  cv::sepFilter2D(image, out, CV_64F, kernel, kernel, cv::Point(-1, -1), 0.0, cv::BORDER_CONSTANT);
  return out;
}

}  // namespace

double ssim(const std::vector<float>& image, const std::vector<float>& reference, int width, int height, std::vector<float>* gradient) {
  const cv::Mat x_all(height, width, CV_32FC3, const_cast<float*>(image.data()));
  const cv::Mat y_all(height, width, CV_32FC3, const_cast<float*>(reference.data()));
  std::vector<cv::Mat> xs, ys;
  cv::split(x_all, xs);
  cv::split(y_all, ys);
  if (gradient != nullptr) gradient->assign(image.size(), 0.0f);
  const double count = 3.0 * static_cast<double>(width) * static_cast<double>(height);
  double total = 0.0;
  for (int c = 0; c < 3; ++c) {
    cv::Mat x, y;
    xs[static_cast<std::size_t>(c)].convertTo(x, CV_64F);
    ys[static_cast<std::size_t>(c)].convertTo(y, CV_64F);
    const cv::Mat mu_x = window(x), mu_y = window(y);
    const cv::Mat xx = window(x.mul(x)), yy = window(y.mul(y)), xy = window(x.mul(y));
    const cv::Mat mu_xx = mu_x.mul(mu_x), mu_yy = mu_y.mul(mu_y), mu_xy = mu_x.mul(mu_y);
    const cv::Mat sigma_x = xx - mu_xx, sigma_y = yy - mu_yy, sigma_xy = xy - mu_xy;
    const cv::Mat a = 2.0 * mu_xy + kC1, b = 2.0 * sigma_xy + kC2;
    const cv::Mat c_term = mu_xx + mu_yy + kC1, d = sigma_x + sigma_y + kC2;
    cv::Mat map;
    cv::divide(a.mul(b), c_term.mul(d), map);
    total += cv::sum(map)[0];
    if (gradient == nullptr) continue;
    // s = a b / (c d): ds/dmu_x, ds/dsigma_x, ds/dsigma_xy per window position, divided by the
    // number of terms of the mean, then through the windowed moments back to the pixels.
    cv::Mat cd = c_term.mul(d);
    cv::Mat ds_dmu_x, ds_dsigma_x, ds_dsigma_xy;
    cv::divide(2.0 * mu_y.mul(b), cd, ds_dmu_x);
    cv::Mat tmp;
    cv::divide(a.mul(b).mul(2.0 * mu_x), cd.mul(c_term), tmp);
    ds_dmu_x -= tmp;
    cv::divide(-a.mul(b), cd.mul(d), ds_dsigma_x);
    cv::divide(2.0 * a, cd, ds_dsigma_xy);
    // sigma_x = E[x^2] - mu_x^2, sigma_xy = E[xy] - mu_x mu_y.
    const cv::Mat dL_dmu = (ds_dmu_x - 2.0 * mu_x.mul(ds_dsigma_x) - mu_y.mul(ds_dsigma_xy)) / count;
    const cv::Mat dL_dxx = ds_dsigma_x / count, dL_dxy = ds_dsigma_xy / count;
    const cv::Mat dx = window(dL_dmu) + 2.0 * x.mul(window(dL_dxx)) + y.mul(window(dL_dxy));
    for (int row = 0; row < height; ++row) {
      const double* in = dx.ptr<double>(row);
      float* out = gradient->data() + 3 * static_cast<std::size_t>(row) * static_cast<std::size_t>(width);
      for (int col = 0; col < width; ++col) out[3 * col + c] = static_cast<float>(in[col]);
    }
  }
  return total / count;
}

}  // namespace hanzo::fusion::neural
