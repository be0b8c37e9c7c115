#include "emu/solvers/fem/rigid_bones.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <stdexcept>
#include <string>
#include <cstdio>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "emu/energy/joint_spring.h"
#include "emu/linalg/rotation.h"

namespace emu {

RigidBones::RigidBones(const Model& model, const UnknownLayout& layout)
    : model_(model), layout_(layout), diag_(bbox_diagonal(model.rest)), bones_(layout.num_bones) {
  const BoneForest forest(layout, diag_);
  order_ = forest.order;
  for (int b = 0; b < layout.num_bones; ++b) {
    static_cast<BoneForest::Node&>(bones_[b]) = forest.bones[b];
    bones_[b].dofs = bones_[b].kind == Kind::Free ? 6 : bones_[b].kind == Kind::Ball ? 3 : 1;
  }
  for (Eigen::Index t = 0; t < model.tets.rows() && layout.num_bones; ++t) {
    if (layout.is_bone_tet(t)) continue;
    for (int a = 0; a < 4; ++a)
      if (layout.vertex_bone(model.tets(t, a)) >= 0) {
        touching_.push_back(static_cast<int>(t));
        break;
      }
  }
  for (Eigen::Index v = 0; v < model.rest.rows(); ++v)
    if (layout.vertex_bone(v) >= 0) bones_[layout.vertex_bone(v)].vertices.push_back(static_cast<int>(v));
  for (int b = 0; b < layout.num_bones; ++b) {
    bones_[b].offset = dofs_;
    dofs_ += bones_[b].dofs;
  }
}

BonePoses RigidBones::begin(const LoadCase& load, const Eigen::MatrixX3d& x, const Eigen::MatrixX3d* initial) {
  BonePoses poses(bones_.size());
  for (int b : order_) {
    const Bone& B = bones_[b];
    BonePose& pose = poses[b];
    // Where each joint point must be: a pinned vertex's target, a declared joint's.
    auto target = [&](int i) -> Vec3 {
      const JointPoint& j = layout_.joints[i];
      if (j.vertex >= 0) return x.row(j.vertex).transpose();
      if (load.joint_targets.rows()) return load.joint_targets.row(j.declared).transpose();
      return j.rest;
    };
    Eigen::MatrixX3d Xb(B.vertices.size(), 3), Yb(B.vertices.size(), 3);
    for (size_t i = 0; i < B.vertices.size(); ++i) {
      Xb.row(i) = model_.rest.row(B.vertices[i]);
      Yb.row(i) = (initial ? *initial : model_.rest).row(B.vertices[i]);
    }
    pose.R = initial ? best_rotation(Xb, Yb) : Mat3::Identity();
    if (B.parent >= 0) {  // on its parent's joint; a hinge turned about its axis only
      const BonePose& q = poses[B.parent];
      pose.p = q.R * (B.P - bones_[B.parent].P) + q.p;
      if (B.kind == Kind::Hinge) {
        pose.axis = q.R * B.rest_axis;
        if (!initial) pose.R = q.R;
        pose.R = rotation_between((pose.R * B.rest_axis).normalized(), pose.axis) * pose.R;
      } else if (!initial) {
        pose.R = q.R;
      }
      continue;
    }
    if (B.kind == Kind::Free) {
      pose.p = Yb.colwise().mean().transpose() - pose.R * (Xb.colwise().mean().transpose() - B.P);
      continue;
    }
    pose.p = target(B.anchors[0]);
    if (B.kind == Kind::Hinge) {
      const int i0 = B.anchors[0], i1 = B.anchors[B.axis_end];
      const Vec3 rest_axis = layout_.joints[i1].rest - layout_.joints[i0].rest;
      const Vec3 target_axis = target(i1) - target(i0);
      if (std::abs(target_axis.norm() - rest_axis.norm()) > 1e-6 * rest_axis.norm())
        throw std::invalid_argument("the hinge of movable bone " + std::to_string(b) +
                                    " is stretched by its pinned vertices' targets (move them rigidly)");
      pose.R = rotation_between((pose.R * rest_axis).normalized(), target_axis.normalized()) * pose.R;
      pose.axis = target_axis.normalized();
    }
  }
  return poses;
}

void RigidBones::add_vertex_hessian(const BonePoses& poses, const Eigen::MatrixX3d& x,
                                    const Eigen::SparseMatrix<double>& H, Eigen::MatrixXd& Hsb,
                                    Eigen::MatrixXd& Hbb) const {
  // Column dof j = 3 w + c of a bone vertex w: its position moves by J_w db, so
  // entry H(i, j) adds H(i, j) J_w.row(c) to row i's border (a free vertex) or,
  // through J_u.row(r)', to Hbb (a bone vertex u).
  Eigen::Matrix<double, 3, Eigen::Dynamic> Jw(3, dofs_), Ju(3, dofs_);
  for (int j = 0; j < H.outerSize(); ++j) {
    const int w = j / 3, c = j % 3, bw = layout_.vertex_bone(w);
    if (bw < 0 || layout_.free_index(w) >= 0) continue;
    vertex_jacobian(bw, x.row(w).transpose(), poses, Jw);
    for (Eigen::SparseMatrix<double>::InnerIterator it(H, j); it; ++it) {
      const int i = static_cast<int>(it.row()), u = i / 3, r = i % 3;
      if (layout_.free_index(u) >= 0) {
        Hsb.row(3 * layout_.free_index(u) + r) += it.value() * Jw.row(c);
      } else if (layout_.vertex_bone(u) >= 0) {
        vertex_jacobian(layout_.vertex_bone(u), x.row(u).transpose(), poses, Ju);
        Hbb += it.value() * Ju.row(r).transpose() * Jw.row(c);
      }
    }
  }
}

Eigen::Matrix<double, 3, Eigen::Dynamic> RigidBones::axes(int b, const BonePoses& poses) const {
  if (bones_[b].kind == Kind::Hinge) return poses[b].axis;
  return Mat3::Identity();
}

void RigidBones::vertex_jacobian(int b, const Vec3& x, const BonePoses& poses,
                                 Eigen::Matrix<double, 3, Eigen::Dynamic>& J) const {
  // d/dtheta of exp(theta [u]_x) about pivot p: u x (x - p) = -[x - p]_x u for
  // each bone of the chain; a free root's translation moves every vertex below it.
  J.setZero(3, dofs_);
  for (int a : bones_[b].chain) {
    const Bone& A = bones_[a];
    const Vec3 r = x - poses[a].p;
    if (A.kind == Kind::Hinge) {
      J.col(A.offset) = poses[a].axis.cross(r);
    } else {
      J.block<3, 3>(0, A.offset) = -cross_matrix(r);
      if (A.kind == Kind::Free) J.block<3, 3>(0, A.offset + 3).setIdentity();
    }
  }
}

BonePoses RigidBones::moved(const BonePoses& poses, const Eigen::VectorXd& db, double s) const {
  // The deepest bones' increments first: bone b's turns b and everything below
  // it about b's pivot before the step (which only the bones above b move).
  BonePoses out = poses;
  for (auto it = order_.rbegin(); it != order_.rend(); ++it) {
    const int b = *it;
    const Bone& B = bones_[b];
    Vec3 w, t = Vec3::Zero();
    if (B.kind == Kind::Hinge) {
      w = s * db(B.offset) * poses[b].axis;
    } else {
      w = s * db.segment<3>(B.offset);
      if (B.kind == Kind::Free) t = s * db.segment<3>(B.offset + 3);
    }
    const Mat3 Q = rotation_exp(w);
    const Vec3 c = poses[b].p;
    for (int d : B.below) {
      out[d].R = Q * out[d].R;
      if (d != b) {
        out[d].p = c + Q * (out[d].p - c);
        out[d].axis = Q * out[d].axis;
      }
      out[d].p += t;
    }
  }
  return out;
}

void RigidBones::place(const BonePoses& poses, Eigen::MatrixX3d& x) const {
  for (size_t b = 0; b < bones_.size(); ++b)
    for (int v : bones_[b].vertices)
      x.row(v) = (poses[b].R * (model_.rest.row(v).transpose() - bones_[b].P) + poses[b].p).transpose();
}

double RigidBones::spring_energy(const BonePoses& poses) const {
  const Eigen::VectorXd& k = model_.bone_stiffness;
  double e = 0;
  for (int b = 0; b < k.size(); ++b) e += joint_spring::energy(poses[b].R, k(b));
  return e;
}

void RigidBones::gradient(const BonePoses& poses, const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& f,
                          Eigen::VectorXd& gb) const {
  gb.setZero(dofs_);
  Eigen::Matrix<double, 3, Eigen::Dynamic> J(3, dofs_);
  for (size_t b = 0; b < bones_.size(); ++b)
    for (int v : bones_[b].vertices) {
      vertex_jacobian(static_cast<int>(b), x.row(v).transpose(), poses, J);
      gb.noalias() += J.transpose() * f.row(v).transpose();
    }
  // A spring on R_b: every turn of b's chain turns R_b (R_b <- exp([u]_x) R_b).
  const Eigen::VectorXd& k = model_.bone_stiffness;
  for (int b = 0; b < k.size(); ++b) {
    const Vec3 gw = joint_spring::expmap_gradient(poses[b].R, k(b));
    for (int a : bones_[b].chain) {
      const Bone& A = bones_[a];
      if (A.kind == Kind::Hinge) gb(A.offset) += poses[a].axis.dot(gw);
      else gb.segment<3>(A.offset) += gw;
    }
  }
}

double RigidBones::gradient_norm(double soft_norm2, const Eigen::VectorXd& gb) const {
  double n2 = soft_norm2;
  for (const Bone& B : bones_)
    for (int i = 0; i < B.dofs; ++i) {
      const double scale = (B.kind == Kind::Free && i >= 3) ? 1.0 : 1.0 / diag_;
      n2 += std::pow(gb(B.offset + i) * scale, 2);
    }
  return std::sqrt(n2);
}

void RigidBones::assemble_border(const BonePoses& poses, const std::vector<double>& element,
                                 const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& f, bool exact,
                                 Eigen::MatrixXd& Hsb, Eigen::MatrixXd& Hbb) const {
  Hsb.setZero(3 * layout_.num_free, dofs_);
  Hbb.setZero(dofs_, dofs_);
  Eigen::Matrix<double, 3, Eigen::Dynamic> Jc(3, dofs_), Ja(3, dofs_);
  for (int t : touching_) {
    const Eigen::Map<const Mat12> K(element.data() + t * 144);
    for (int c = 0; c < 4; ++c) {
      const int vc = model_.tets(t, c), bc = layout_.vertex_bone(vc);
      if (bc < 0) continue;
      vertex_jacobian(bc, x.row(vc).transpose(), poses, Jc);
      for (int a = 0; a < 4; ++a) {
        const int va = model_.tets(t, a);
        const Mat3 Kac = K.block<3, 3>(3 * a, 3 * c);
        if (layout_.free_index(va) >= 0) {
          Hsb.middleRows<3>(3 * layout_.free_index(va)).noalias() += Kac * Jc;
        } else if (layout_.vertex_bone(va) >= 0) {
          vertex_jacobian(layout_.vertex_bone(va), x.row(va).transpose(), poses, Ja);
          Hbb.noalias() += Ja.transpose() * (Kac * Jc);
        }
      }
    }
  }
  add_rotation_term(poses, x, f, exact, Hbb);
}

void RigidBones::add_rotation_term(const BonePoses& poses, const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& f,
                                   bool exact, Eigen::MatrixXd& Hbb) const {
  // In world axes, 3 per bone of each tree: W_ab (header), then clamped to PSD
  // per tree (filtered Newton) and projected on each bone's turn axes.
  const Eigen::VectorXd& k = model_.bone_stiffness;
  std::vector<Mat3> M(bones_.size(), Mat3::Zero());
  for (size_t d = 0; d < bones_.size(); ++d)
    for (int v : bones_[d].vertices) {
      const Vec3 xv = x.row(v).transpose(), fv = f.row(v).transpose();
      for (int a : bones_[d].chain) M[a] += fv * (xv - poses[a].p).transpose();
    }
  std::vector<int> local(bones_.size(), -1);
  for (int root : order_) {
    if (bones_[root].parent >= 0) continue;
    const std::vector<int>& tree = bones_[root].below;
    const int n = static_cast<int>(tree.size());
    for (int i = 0; i < n; ++i) local[tree[i]] = i;
    Eigen::MatrixXd W = Eigen::MatrixXd::Zero(3 * n, 3 * n);
    for (int b : tree) {
      const Mat3& Mb = M[b];
      const double tr = Mb.trace();
      W.block<3, 3>(3 * local[b], 3 * local[b]) += 0.5 * (Mb + Mb.transpose()) - tr * Mat3::Identity();
      for (int a : bones_[b].chain) {
        if (a == b) continue;
        const Mat3 Wab = Mb.transpose() - tr * Mat3::Identity();
        W.block<3, 3>(3 * local[a], 3 * local[b]) += Wab;
        W.block<3, 3>(3 * local[b], 3 * local[a]) += Wab.transpose();
      }
      if (b >= k.size()) continue;
      const Vec3 gw = joint_spring::expmap_gradient(poses[b].R, k(b));
      const Mat3 Hw = joint_spring::expmap_hessian(poses[b].R, k(b));
      const std::vector<int>& chain = bones_[b].chain;  // root first: chain[i] above chain[j] for i < j
      for (size_t i = 0; i < chain.size(); ++i) {
        W.block<3, 3>(3 * local[chain[i]], 3 * local[chain[i]]) += Hw;
        for (size_t j = i + 1; j < chain.size(); ++j) {
          const Mat3 Wij = Hw - 0.5 * cross_matrix(gw);
          W.block<3, 3>(3 * local[chain[i]], 3 * local[chain[j]]) += Wij;
          W.block<3, 3>(3 * local[chain[j]], 3 * local[chain[i]]) += Wij.transpose();
        }
      }
    }
    if (!exact) {  // filtered Newton: clamp the rotation term's negative curvature
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(W);
      W = es.eigenvectors() * es.eigenvalues().cwiseMax(0.0).asDiagonal() * es.eigenvectors().transpose();
    }
    for (int a : tree)
      for (int b : tree) {
        const auto Ua = axes(a, poses), Ub = axes(b, poses);
        Hbb.block(bones_[a].offset, bones_[b].offset, Ua.cols(), Ub.cols()) +=
            Ua.transpose() * W.block<3, 3>(3 * local[a], 3 * local[b]) * Ub;
      }
  }
}

bool RigidBones::solve_schur(const BonePoses& poses, const Eigen::MatrixXd& S, const Eigen::VectorXd& rb, bool exact,
                             Eigen::VectorXd& db, std::vector<NeutralMode>& neutral) const {
  Eigen::LLT<Eigen::MatrixXd> llt(S);
  if (llt.info() == Eigen::Success &&
      llt.matrixLLT().diagonal().minCoeff() > 1e-6 * std::sqrt(S.diagonal().maxCoeff())) {
    db = llt.solve(rb);
    return true;
  }
  if (exact) return false;
  // A bone direction nothing resists (a neutral mode): S is singular there.
  // Step with its pseudo-inverse (that direction is left alone) and say which.
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(S);
  const Eigen::VectorXd& lam = es.eigenvalues();
  const double lmax = lam.cwiseAbs().maxCoeff();
  db.setZero(dofs_);
  neutral.clear();
  for (int i = 0; i < dofs_; ++i) {
    const Eigen::VectorXd vi = es.eigenvectors().col(i);
    if (lam(i) > 1e-10 * lmax) {
      db += vi * (vi.dot(rb) / lam(i));
      continue;
    }
    if (lam(i) < -1e-10 * lmax) return false;  // filtered S is PSD up to round-off
    int best = 0;
    for (int b = 1; b < size(); ++b)
      if (vi.segment(bones_[b].offset, bones_[b].dofs).norm() >
          vi.segment(bones_[best].offset, bones_[best].dofs).norm())
        best = b;
    const Bone& B = bones_[best];
    Vec3 axis = B.kind == Kind::Hinge ? poses[best].axis : Vec3(vi.segment<3>(B.offset).normalized());
    if (B.kind == Kind::Free && vi.segment<3>(B.offset).norm() < vi.segment<3>(B.offset + 3).norm())
      axis = vi.segment<3>(B.offset + 3).normalized();  // free to slide, not turn
    neutral.push_back({best, axis});
  }
  return true;
}

std::string RigidBones::weakest_turn(const BonePoses& poses, const Eigen::MatrixXd& S) const {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (S + S.transpose()));
  const Eigen::VectorXd& lam = es.eigenvalues();
  const double lmax = lam.cwiseAbs().maxCoeff();
  if (!(lmax > 0) || lam(0) > kWeakTurn * lmax) return "";
  const Eigen::VectorXd v = es.eigenvectors().col(0);
  int best = 0;
  for (int b = 1; b < size(); ++b)
    if (v.segment(bones_[b].offset, bones_[b].dofs).norm() > v.segment(bones_[best].offset, bones_[best].dofs).norm())
      best = b;
  const Bone& B = bones_[best];
  const Vec3 axis = B.kind == Kind::Hinge ? poses[best].axis : Vec3(v.segment<3>(B.offset).normalized());
  char text[320];
  std::snprintf(text, sizeof text,
                "; the turn of movable bone %d about (%.2f, %.2f, %.2f) is resisted %.1e times as stiffly as the "
                "stiffest bone motion (a near-neutral mode: the energy is nearly flat along it, so Newton "
                "converges slowly); a joint_stiffness on that bone, an antagonist muscle or fixing a bone settles it",
                best, axis(0), axis(1), axis(2), std::max(lam(0), 0.0) / lmax);
  return text;
}

}  // namespace emu
