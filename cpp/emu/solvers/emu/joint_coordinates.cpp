#include "emu/solvers/emu/joint_coordinates.h"

#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "emu/linalg/rotation.h"

namespace emu {
namespace {
/// w with [w]x = skew(M): vee of M's skew part.
Vec3 skew_vee(const Mat3& M) { return 0.5 * Vec3(M(2, 1) - M(1, 2), M(0, 2) - M(2, 0), M(1, 0) - M(0, 1)); }
}  // namespace

JointCoordinates::JointCoordinates(BoneForest forest, int num_soft)
    : forest_(std::move(forest)), num_soft_(num_soft) {
  for (const BoneForest::Node& B : forest_.bones) {
    offset_.push_back(size_);
    dims_.push_back(B.kind == BoneForest::Kind::Hinge ? 1 : 3);
    size_ += dims_.back();
  }
}

Eigen::Matrix<double, 3, Eigen::Dynamic> JointCoordinates::axes(const Mat9X& F, int b) const {
  if (forest_.bones[b].kind != BoneForest::Kind::Hinge) return Mat3::Identity();
  return (rotation(F, b) * forest_.bones[b].rest_axis).normalized();  // = R_parent e on the joints
}

Eigen::MatrixXd JointCoordinates::turn_map(const Mat9X& F) const {
  Eigen::MatrixXd T = Eigen::MatrixXd::Zero(3 * bones(), size_);
  for (int j = 0; j < bones(); ++j) {
    const auto A = axes(F, j);
    for (int b : forest_.bones[j].below) T.block(3 * b, offset_[j], 3, dims_[j]) = A;
  }
  return T;
}

Eigen::VectorXd JointCoordinates::fit(const Eigen::MatrixXd& T, const Eigen::VectorXd& omega) const {
  // T has full column rank (triangular along each chain): T'T is definite.
  return (T.transpose() * T).ldlt().solve(T.transpose() * omega);
}

Eigen::VectorXd JointCoordinates::world_turns(const Mat9X& F, const Mat9X& v) const {
  Eigen::VectorXd omega(3 * bones());
  for (int b = 0; b < bones(); ++b)
    omega.segment<3>(3 * b) = skew_vee(unflatten(v.col(num_soft_ + b)) * rotation(F, b).transpose());
  return omega;
}

Eigen::VectorXd JointCoordinates::coordinates(const Mat9X& F, const Mat9X& v) const {
  return fit(turn_map(F), world_turns(F, v));
}

void JointCoordinates::project(const Mat9X& F, Mat9X& v) const {
  const Eigen::MatrixXd T = turn_map(F);
  const Eigen::VectorXd omega = T * fit(T, world_turns(F, v));
  for (int b = 0; b < bones(); ++b)
    v.col(num_soft_ + b) = flatten(Mat3(cross_matrix(omega.segment<3>(3 * b)) * rotation(F, b)));
}

void JointCoordinates::retract(const Mat9X& F, const Mat9X& d, double s, Mat9X& out) const {
  const int ns = num_soft_;
  out.resize(F.rows(), F.cols());
  out.leftCols(ns) = F.leftCols(ns) + s * d.leftCols(ns);
  const Eigen::VectorXd theta = coordinates(F, d);
  std::vector<Mat3> turned(bones());  // exp(s tau_r) ... exp(s tau_b): the tree's turn of bone b
  for (int b : forest_.order) {
    const BoneForest::Node& B = forest_.bones[b];
    const Vec3 tau = axes(F, b) * theta.segment(offset_[b], dims_[b]);
    const Mat3 Q = rotation_exp(s * tau);
    turned[b] = B.parent >= 0 ? Mat3(turned[B.parent] * Q) : Q;
    Mat3 R = turned[b] * rotation(F, b);
    if (B.kind == BoneForest::Kind::Hinge && B.parent >= 0) {  // the axis on the parent's, to round-off
      const Mat3 Rp = unflatten(out.col(ns + B.parent));
      R = rotation_between((R * B.rest_axis).normalized(), (Rp * B.rest_axis).normalized()) * R;
    }
    out.col(ns + b) = flatten(R);
  }
}

Eigen::VectorXd JointCoordinates::curvature_gradient(const Mat9X& F, const Mat9X& g,
                                                     const Eigen::VectorXd& theta) const {
  const int nb = bones();
  std::vector<Vec3> tau(nb), omega(nb), gamma(nb);
  for (int b : forest_.order) {
    const BoneForest::Node& B = forest_.bones[b];
    tau[b] = axes(F, b) * theta.segment(offset_[b], dims_[b]);
    omega[b] = B.parent >= 0 ? Vec3(omega[B.parent] + tau[b]) : tau[b];
    gamma[b] = 2.0 * skew_vee(unflatten(g.col(num_soft_ + b)) * rotation(F, b).transpose());
  }
  Eigen::VectorXd grad = Eigen::VectorXd::Zero(size_);
  for (int j = 0; j < nb; ++j) {
    const BoneForest::Node& J = forest_.bones[j];
    const Vec3 above = J.parent >= 0 ? omega[J.parent] : Vec3::Zero();
    Vec3 sum = Vec3::Zero();
    for (int b : J.below) sum += (omega[b] - tau[j] - 2.0 * above).cross(gamma[b]);
    grad.segment(offset_[j], dims_[j]) = 0.5 * axes(F, j).transpose() * sum;
  }
  return grad;
}

void JointCoordinates::add_tangent(const Mat9X& F, const Eigen::MatrixXd& T, const Eigen::VectorXd& grad,
                                   Mat9X& out) const {
  // <[omega']x R, [w]x R> = 2 omega'.w: the tangent w = T (T'T)^-1 grad / 2 gives <v', w> = theta'.grad.
  const Eigen::VectorXd w = 0.5 * (T * (T.transpose() * T).ldlt().solve(grad));
  for (int b = 0; b < bones(); ++b)
    out.col(num_soft_ + b) += flatten(Mat3(cross_matrix(w.segment<3>(3 * b)) * rotation(F, b)));
}

Eigen::MatrixXd JointCoordinates::rotation_term(const Mat9X& F, const Mat9X& g, bool clamp) const {
  const Eigen::MatrixXd T = turn_map(F);
  Eigen::MatrixXd W(size_, size_);
  for (int i = 0; i < size_; ++i) W.col(i) = curvature_gradient(F, g, Eigen::VectorXd::Unit(size_, i));
  W = 0.5 * (W + W.transpose()).eval();
  for (int b = 0; b < bones(); ++b) {
    const Mat3 M = unflatten(g.col(num_soft_ + b)) * rotation(F, b).transpose();
    const Mat3 K = 0.5 * (M + M.transpose()) - M.trace() * Mat3::Identity();
    const auto Tb = T.middleRows(3 * b, 3);
    W.noalias() += Tb.transpose() * K * Tb;
  }
  if (!clamp) return W;
  // per tree: the trees' coordinates do not mix, so one decomposition of W is the same
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(W);
  return es.eigenvectors() * es.eigenvalues().cwiseMax(0.0).asDiagonal() * es.eigenvectors().transpose();
}

void JointCoordinates::add_rotation_product(const Mat9X& F, const Eigen::MatrixXd& W, const Mat9X& v,
                                            Mat9X& out) const {
  const Eigen::MatrixXd T = turn_map(F);
  add_tangent(F, T, W * fit(T, world_turns(F, v)), out);
}

void JointCoordinates::project_onto_joints(Mat9X& F, const Eigen::MatrixX3d& h) const {
  for (int b : forest_.order) {
    const BoneForest::Node& B = forest_.bones[b];
    if (B.kind != BoneForest::Kind::Hinge) continue;
    Vec3 target;
    if (B.parent >= 0) {
      target = rotation(F, B.parent) * B.rest_axis;
    } else {
      const Eigen::Index i0 = B.anchors[0], i1 = B.anchors[B.axis_end];
      target = (h.row(i1) - h.row(i0)).transpose();  // rest_axis points from anchor 0 to axis_end
    }
    const Mat3 R = rotation(F, b);
    F.col(num_soft_ + b) = flatten(Mat3(rotation_between((R * B.rest_axis).normalized(), target.normalized()) * R));
  }
}

}  // namespace emu
