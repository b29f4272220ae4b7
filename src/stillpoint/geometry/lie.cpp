#include "stillpoint/geometry/lie.hpp"

#include <cmath>

namespace sp::geo {
namespace {

// Below this angle the closed forms lose digits to cancellation; Taylor series are used instead.
constexpr double kSmallAngle = 1e-4;
constexpr double kSmallAngleQ = 1e-2;

Eigen::Quaterniond quat_exp(const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const double half = 0.5 * theta;
  // sin(theta/2)/theta, exact series for tiny angles.
  const double k = theta < kSmallAngle ? 0.5 - theta * theta / 48.0 : std::sin(half) / theta;
  Eigen::Quaterniond q(std::cos(half), k * phi.x(), k * phi.y(), k * phi.z());
  q.normalize();
  return q;
}

Eigen::Vector3d quat_log(Eigen::Quaterniond q) {
  q.normalize();
  if (q.w() < 0) q.coeffs() = -q.coeffs();  // the short way round, angle in [0, pi]
  const Eigen::Vector3d v = q.vec();
  const double n = v.norm();
  if (n < 1e-12) return (2.0 / q.w()) * v;
  return (2.0 * std::atan2(n, q.w()) / n) * v;
}

// Coefficients of Jl(phi) = I + a hat + b hat^2 (Jr flips the sign of a).
void so3_jacobian_coeffs(double theta, double& a, double& b) {
  if (theta < kSmallAngle) {
    const double t2 = theta * theta;
    a = 0.5 - t2 / 24.0;
    b = 1.0 / 6.0 - t2 / 120.0;
    return;
  }
  const double s = std::sin(0.5 * theta);
  a = 2.0 * s * s / (theta * theta);  // (1 - cos)/theta^2 without cancellation
  b = (theta - std::sin(theta)) / (theta * theta * theta);
}

// Coefficient c of the inverse: Jl^-1 = I - hat/2 + c hat^2 (Jr^-1 flips the sign of hat/2).
double so3_jacobian_inv_coeff(double theta) {
  if (theta < kSmallAngle) return 1.0 / 12.0 + theta * theta / 720.0;
  const double half = 0.5 * theta;
  // 1/theta^2 - (1 + cos)/(2 theta sin), written with cot(theta/2) so it is finite at pi.
  return 1.0 / (theta * theta) - std::cos(half) / (2.0 * theta * std::sin(half));
}

// Upper-right block Q(rho, phi) of the SE(3) left Jacobian.
Eigen::Matrix3d se3_q(const Eigen::Vector3d& rho, const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const Eigen::Matrix3d P = hat(phi);
  const Eigen::Matrix3d Rh = hat(rho);
  const Eigen::Matrix3d PR = P * Rh;
  const Eigen::Matrix3d RP = Rh * P;
  const Eigen::Matrix3d PRP = PR * P;
  double c1, c2, c3;
  const double t2 = theta * theta;
  if (theta < kSmallAngleQ) {
    c1 = 1.0 / 6.0 - t2 / 120.0;
    c2 = 1.0 / 24.0 - t2 / 720.0;
    c3 = 1.0 / 120.0 - t2 / 2520.0;
  } else {
    const double s = std::sin(theta), c = std::cos(theta);
    c1 = (theta - s) / (t2 * theta);
    c2 = (t2 + 2.0 * c - 2.0) / (2.0 * t2 * t2);
    c3 = (2.0 * theta - 3.0 * s + theta * c) / (2.0 * t2 * t2 * theta);
  }
  return 0.5 * Rh + c1 * (PR + RP + PRP) + c2 * (P * PR + RP * P - 3.0 * PRP) + c3 * (PRP * P + P * PRP);
}

}  // namespace

Eigen::Matrix3d hat(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Eigen::Matrix3d so3_exp(const Eigen::Vector3d& phi) { return quat_exp(phi).toRotationMatrix(); }

Eigen::Vector3d so3_log(const Eigen::Matrix3d& R) { return quat_log(Eigen::Quaterniond(R)); }

Eigen::Matrix3d so3_left_jacobian(const Eigen::Vector3d& phi) {
  double a, b;
  so3_jacobian_coeffs(phi.norm(), a, b);
  const Eigen::Matrix3d P = hat(phi);
  return Eigen::Matrix3d::Identity() + a * P + b * P * P;
}

Eigen::Matrix3d so3_right_jacobian(const Eigen::Vector3d& phi) { return so3_left_jacobian(-phi); }

Eigen::Matrix3d so3_left_jacobian_inv(const Eigen::Vector3d& phi) {
  const double c = so3_jacobian_inv_coeff(phi.norm());
  const Eigen::Matrix3d P = hat(phi);
  return Eigen::Matrix3d::Identity() - 0.5 * P + c * P * P;
}

Eigen::Matrix3d so3_right_jacobian_inv(const Eigen::Vector3d& phi) { return so3_left_jacobian_inv(-phi); }

double rotation_angle(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
}

SE3::SE3(const Eigen::Quaterniond& q, const Eigen::Vector3d& t) : q_(q.normalized()), t_(t) {}

SE3::SE3(const Eigen::Matrix3d& R, const Eigen::Vector3d& t)
    : q_(Eigen::Quaterniond(R).normalized()), t_(t) {}

SE3 SE3::exp(const Vec6& xi) {
  const Eigen::Vector3d rho = xi.head<3>();
  const Eigen::Vector3d phi = xi.tail<3>();
  return SE3(quat_exp(phi), so3_left_jacobian(phi) * rho);
}

Vec6 SE3::log() const {
  Vec6 xi;
  const Eigen::Vector3d phi = quat_log(q_);
  xi.head<3>() = so3_left_jacobian_inv(phi) * t_;
  xi.tail<3>() = phi;
  return xi;
}

SE3 SE3::inverse() const {
  const Eigen::Quaterniond qi = q_.conjugate();
  return SE3(qi, -(qi * t_));
}

SE3 SE3::operator*(const SE3& other) const { return SE3(q_ * other.q_, q_ * other.t_ + t_); }

Eigen::Matrix4d SE3::matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = rotation();
  m.topRightCorner<3, 1>() = t_;
  return m;
}

Mat6 SE3::adjoint() const {
  const Eigen::Matrix3d R = rotation();
  Mat6 A = Mat6::Zero();
  A.topLeftCorner<3, 3>() = R;
  A.topRightCorner<3, 3>() = hat(t_) * R;
  A.bottomRightCorner<3, 3>() = R;
  return A;
}

SE3 SE3::from_matrix(const Eigen::Matrix4d& M) {
  // Project onto SO(3) so a slightly non-orthonormal input still gives a proper rotation.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(M.topLeftCorner<3, 3>(),
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d R = svd.matrixU() * svd.matrixV().transpose();
  if (R.determinant() < 0) {
    Eigen::Matrix3d U = svd.matrixU();
    U.col(2) *= -1;
    R = U * svd.matrixV().transpose();
  }
  return SE3(R, M.topRightCorner<3, 1>());
}

Mat6 se3_ad(const Vec6& xi) {
  Mat6 A = Mat6::Zero();
  const Eigen::Matrix3d P = hat(xi.tail<3>());
  A.topLeftCorner<3, 3>() = P;
  A.topRightCorner<3, 3>() = hat(xi.head<3>());
  A.bottomRightCorner<3, 3>() = P;
  return A;
}

Mat6 se3_left_jacobian(const Vec6& xi) {
  const Eigen::Vector3d phi = xi.tail<3>();
  const Eigen::Matrix3d J = so3_left_jacobian(phi);
  Mat6 out = Mat6::Zero();
  out.topLeftCorner<3, 3>() = J;
  out.topRightCorner<3, 3>() = se3_q(xi.head<3>(), phi);
  out.bottomRightCorner<3, 3>() = J;
  return out;
}

Mat6 se3_left_jacobian_inv(const Vec6& xi) {
  const Eigen::Vector3d phi = xi.tail<3>();
  const Eigen::Matrix3d Ji = so3_left_jacobian_inv(phi);
  Mat6 out = Mat6::Zero();
  out.topLeftCorner<3, 3>() = Ji;
  out.topRightCorner<3, 3>() = -Ji * se3_q(xi.head<3>(), phi) * Ji;
  out.bottomRightCorner<3, 3>() = Ji;
  return out;
}

Mat6 se3_right_jacobian(const Vec6& xi) { return se3_left_jacobian(-xi); }

Mat6 se3_right_jacobian_inv(const Vec6& xi) { return se3_left_jacobian_inv(-xi); }

}  // namespace sp::geo
