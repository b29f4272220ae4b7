#pragma once
// SO(3) / SE(3) helpers. Tangent vectors of SE(3) are ordered xi = [rho (translation part); phi
// (rotation)], and exp(xi) = [[exp(phi), Jl(phi) rho], [0, 1]]. Every function is small-angle safe
// (Taylor series for tiny angles) and robust near pi.
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace sp::geo {

using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat6 = Eigen::Matrix<double, 6, 6>;

// Skew-symmetric matrix: hat(a) * b == a.cross(b).
Eigen::Matrix3d hat(const Eigen::Vector3d& v);
// Rodrigues' formula.
Eigen::Matrix3d so3_exp(const Eigen::Vector3d& phi);
// Rotation vector with angle in [0, pi]; the input is assumed orthonormal (it is re-orthonormalised).
Eigen::Vector3d so3_log(const Eigen::Matrix3d& R);
// Right Jacobian: exp(phi + d) ≈ exp(phi) exp(Jr(phi) d).
Eigen::Matrix3d so3_right_jacobian(const Eigen::Vector3d& phi);
Eigen::Matrix3d so3_right_jacobian_inv(const Eigen::Vector3d& phi);
// Left Jacobian: exp(phi + d) ≈ exp(Jl(phi) d) exp(phi); Jl(phi) = Jr(-phi).
Eigen::Matrix3d so3_left_jacobian(const Eigen::Vector3d& phi);
Eigen::Matrix3d so3_left_jacobian_inv(const Eigen::Vector3d& phi);
// Rotation angle in radians, [0, pi]; uses atan2 so it is accurate near 0 and near pi.
double rotation_angle(const Eigen::Matrix3d& R);

// Rigid transform T: p -> R p + t, stored as a unit quaternion and a translation.
class SE3 {
 public:
  SE3() = default;
  SE3(const Eigen::Quaterniond& q, const Eigen::Vector3d& t);
  SE3(const Eigen::Matrix3d& R, const Eigen::Vector3d& t);

  static SE3 exp(const Vec6& xi);
  [[nodiscard]] Vec6 log() const;
  [[nodiscard]] SE3 inverse() const;
  SE3 operator*(const SE3& other) const;
  Eigen::Vector3d operator*(const Eigen::Vector3d& p) const { return q_ * p + t_; }

  [[nodiscard]] const Eigen::Quaterniond& quaternion() const { return q_; }
  [[nodiscard]] Eigen::Matrix3d rotation() const { return q_.toRotationMatrix(); }
  [[nodiscard]] const Eigen::Vector3d& translation() const { return t_; }
  [[nodiscard]] Eigen::Matrix4d matrix() const;
  // Ad(T) with T exp(xi) T^-1 = exp(Ad(T) xi): [[R, hat(t) R], [0, R]].
  [[nodiscard]] Mat6 adjoint() const;
  // Uses the upper-left 3x3 (re-orthonormalised) and the last column.
  static SE3 from_matrix(const Eigen::Matrix4d& M);

 private:
  Eigen::Quaterniond q_ = Eigen::Quaterniond::Identity();
  Eigen::Vector3d t_ = Eigen::Vector3d::Zero();
};

// The small-adjoint ad(xi) = [[hat(phi), hat(rho)], [0, hat(phi)]] (Lie bracket matrix).
Mat6 se3_ad(const Vec6& xi);
// SE(3) left Jacobian: exp(xi + d) ≈ exp(Jl(xi) d) exp(xi), and its inverse (closed form).
Mat6 se3_left_jacobian(const Vec6& xi);
Mat6 se3_left_jacobian_inv(const Vec6& xi);
// Right Jacobians: exp(xi + d) ≈ exp(xi) exp(Jr(xi) d); Jr(xi) = Jl(-xi).
Mat6 se3_right_jacobian(const Vec6& xi);
Mat6 se3_right_jacobian_inv(const Vec6& xi);

}  // namespace sp::geo
