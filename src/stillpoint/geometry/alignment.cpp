#include "stillpoint/geometry/alignment.hpp"

#include <Eigen/Geometry>

#include "stillpoint/common/error.hpp"

namespace sp::geo {

Similarity3 align_umeyama(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                          bool with_scale) {
  if (src.size() != dst.size()) throw Error("align_umeyama: point sets differ in size");
  if (src.size() < 3) throw Error("align_umeyama: need at least 3 point pairs");
  Eigen::Matrix3Xd a(3, src.size());
  Eigen::Matrix3Xd b(3, dst.size());
  for (std::size_t i = 0; i < src.size(); ++i) {
    a.col(static_cast<Eigen::Index>(i)) = src[i];
    b.col(static_cast<Eigen::Index>(i)) = dst[i];
  }
  const Eigen::Matrix4d T = Eigen::umeyama(a, b, with_scale);
  Similarity3 s;
  const Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
  s.scale = with_scale ? std::cbrt(sR.determinant()) : 1.0;
  s.R = sR / s.scale;
  s.t = T.topRightCorner<3, 1>();
  return s;
}

}  // namespace sp::geo
