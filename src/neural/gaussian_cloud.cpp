#include "hanzo/fusion/neural/gaussian_cloud.hpp"

#include <algorithm>

#include "spherical_harmonics.hpp"

namespace hanzo::fusion::neural {

void GaussianCloud::add(const Eigen::Vector3f& mean, const Eigen::Vector3f& log_scales, const Eigen::Vector4f& rotation_wxyz, float opacity_logit_value,
                        const Eigen::Vector3f& sh_dc) {
  position.insert(position.end(), mean.data(), mean.data() + 3);
  log_scale.insert(log_scale.end(), log_scales.data(), log_scales.data() + 3);
  rotation.insert(rotation.end(), rotation_wxyz.data(), rotation_wxyz.data() + 4);
  opacity_logit.push_back(opacity_logit_value);
  const std::size_t first = sh.size();
  sh.resize(first + static_cast<std::size_t>(sh_floats()), 0.0f);
  std::copy(sh_dc.data(), sh_dc.data() + 3, sh.begin() + static_cast<std::ptrdiff_t>(first));
}

namespace {
template <typename T>
void keep_rows(std::vector<T>& values, const std::vector<bool>& keep, std::size_t width) {
  std::size_t out = 0;
  for (std::size_t i = 0; i < keep.size(); ++i) {
    if (!keep[i]) continue;
    if (out != i) std::copy_n(values.begin() + static_cast<std::ptrdiff_t>(i * width), width, values.begin() + static_cast<std::ptrdiff_t>(out * width));
    ++out;
  }
  values.resize(out * width);
}
}  // namespace

void GaussianCloud::filter(const std::vector<bool>& keep) {
  keep_rows(position, keep, 3);
  keep_rows(log_scale, keep, 3);
  keep_rows(rotation, keep, 4);
  keep_rows(opacity_logit, keep, 1);
  keep_rows(sh, keep, static_cast<std::size_t>(sh_floats()));
}

std::vector<std::span<float>> GaussianCloud::parameters() { return {position, log_scale, rotation, opacity_logit, sh}; }

bool GaussianCloud::consistent() const {
  const std::size_t n = size();
  if (sh_degree < 0 || sh_degree > kMaxShDegree) return false;
  if (position.size() != 3 * n || log_scale.size() != 3 * n || rotation.size() != 4 * n || sh.size() != n * static_cast<std::size_t>(sh_floats())) return false;
  const auto finite = [](const std::vector<float>& values) { return std::all_of(values.begin(), values.end(), [](float v) { return std::isfinite(v); }); };
  return finite(position) && finite(log_scale) && finite(rotation) && finite(opacity_logit) && finite(sh);
}

void GaussianGradients::resize_like(const GaussianCloud& cloud) {
  position.assign(cloud.position.size(), 0.0f);
  log_scale.assign(cloud.log_scale.size(), 0.0f);
  rotation.assign(cloud.rotation.size(), 0.0f);
  opacity_logit.assign(cloud.opacity_logit.size(), 0.0f);
  sh.assign(cloud.sh.size(), 0.0f);
  screen_gradient_norm.assign(cloud.size(), 0.0f);
  visible_views.assign(cloud.size(), 0);
}

void GaussianGradients::set_zero() {
  for (std::span<float> group : parameters()) std::fill(group.begin(), group.end(), 0.0f);
  std::fill(screen_gradient_norm.begin(), screen_gradient_norm.end(), 0.0f);
  std::fill(visible_views.begin(), visible_views.end(), 0);
}

std::vector<std::span<float>> GaussianGradients::parameters() { return {position, log_scale, rotation, opacity_logit, sh}; }

Eigen::Vector3f sh_dc_of_colour(const Eigen::Vector3f& colour) { return (colour.array() - 0.5f) / static_cast<float>(detail::kShC0); }

}  // namespace hanzo::fusion::neural
