#include "emu/solvers/rigid_bones.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "emu/energy/joint_spring.h"
#include "emu/linalg/rotation.h"

namespace emu {

RigidBones::RigidBones(const Model& model, const UnknownLayout& layout)
    : model_(model), layout_(layout), diag_(bbox_diagonal(model.rest)), bones_(layout.num_bones) {
  for (size_t i = 0; i < layout.joints.size(); ++i) {
    const JointPoint& j = layout.joints[i];
    if (j.other >= 0)
      throw std::invalid_argument("the FEM solver does not support joints between two movable bones yet (bones " +
                                  std::to_string(j.bone) + " and " + std::to_string(j.other) +
                                  "); use method='emu' or fix one bone");
    bones_[j.bone].anchors.push_back(static_cast<int>(i));
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
    Bone& B = bones_[b];
    if (B.anchors.empty()) {
      B.kind = Kind::Free;
      B.dofs = 6;
      B.P = layout.bone_center.row(b).transpose();
    } else {
      const Vec3 X0 = layout.joints[B.anchors[0]].rest;
      for (size_t i = 1; i < B.anchors.size(); ++i)
        if (B.axis_end < 0 && (layout.joints[B.anchors[i]].rest - X0).norm() > 1e-9 * diag_)
          B.axis_end = static_cast<int>(i);
      B.kind = B.axis_end < 0 ? Kind::Ball : Kind::Hinge;
      B.dofs = B.axis_end < 0 ? 3 : 1;
      if (B.axis_end >= 0) {
        const Vec3 a = (layout.joints[B.anchors[B.axis_end]].rest - X0).normalized();
        for (int i : B.anchors) {
          const Vec3 r = layout.joints[i].rest - X0;
          if ((r - r.dot(a) * a).norm() > 1e-6 * diag_)
            throw std::invalid_argument("movable bone " + std::to_string(b) +
                                        " is welded: its joints with pinned vertices or fixed bones are not on "
                                        "one line; fix the bone instead");
        }
      }
      B.P = X0;
    }
    B.offset = dofs_;
    dofs_ += B.dofs;
  }
}

BonePoses RigidBones::begin(const LoadCase& load, const Eigen::MatrixX3d& x, const Eigen::MatrixX3d* initial) {
  BonePoses poses(bones_.size());
  for (size_t b = 0; b < bones_.size(); ++b) {
    Bone& B = bones_[b];
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
      B.axis = target_axis.normalized();
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
  for (int j = 0; j < H.outerSize(); ++j) {
    const int w = j / 3, c = j % 3, bw = layout_.vertex_bone(w);
    if (bw < 0 || layout_.free_index(w) >= 0) continue;
    const Bone& Bw = bones_[bw];
    const Eigen::RowVectorXd Jw = jacobian(Bw, x.row(w).transpose() - poses[bw].p).row(c);
    for (Eigen::SparseMatrix<double>::InnerIterator it(H, j); it; ++it) {
      const int i = static_cast<int>(it.row()), u = i / 3, r = i % 3;
      if (layout_.free_index(u) >= 0) {
        Hsb.block(3 * layout_.free_index(u) + r, Bw.offset, 1, Bw.dofs) += it.value() * Jw;
      } else if (layout_.vertex_bone(u) >= 0) {
        const int bu = layout_.vertex_bone(u);
        const Bone& Bu = bones_[bu];
        const Eigen::VectorXd Ju = jacobian(Bu, x.row(u).transpose() - poses[bu].p).row(r).transpose();
        Hbb.block(Bu.offset, Bw.offset, Bu.dofs, Bw.dofs) += it.value() * Ju * Jw;
      }
    }
  }
}

Eigen::Matrix<double, 3, Eigen::Dynamic> RigidBones::jacobian(const Bone& B, const Vec3& r) const {
  // d/dw of exp([w]_x) r = w x r = -[r]_x w; a translation moves every vertex.
  Eigen::Matrix<double, 3, Eigen::Dynamic> J(3, B.dofs);
  if (B.kind == Kind::Hinge) {
    J.col(0) = B.axis.cross(r);
  } else {
    J.leftCols<3>() = -cross_matrix(r);
    if (B.kind == Kind::Free) J.rightCols<3>().setIdentity();
  }
  return J;
}

BonePoses RigidBones::moved(const BonePoses& poses, const Eigen::VectorXd& db, double s) const {
  BonePoses out = poses;
  for (size_t b = 0; b < bones_.size(); ++b) {
    const Bone& B = bones_[b];
    Vec3 w, t = Vec3::Zero();
    if (B.kind == Kind::Hinge) {
      w = s * db(B.offset) * B.axis;
    } else {
      w = s * db.segment<3>(B.offset);
      if (B.kind == Kind::Free) t = s * db.segment<3>(B.offset + 3);
    }
    out[b].R = rotation_exp(w) * out[b].R;
    out[b].p += t;
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
  for (size_t b = 0; b < bones_.size(); ++b) {
    const Bone& B = bones_[b];
    for (int v : B.vertices)
      gb.segment(B.offset, B.dofs) += jacobian(B, x.row(v).transpose() - poses[b].p).transpose() * f.row(v).transpose();
  }
  const Eigen::VectorXd& k = model_.bone_stiffness;
  for (int b = 0; b < k.size(); ++b) {
    const Bone& B = bones_[b];
    const Vec3 gw = joint_spring::expmap_gradient(poses[b].R, k(b));
    if (B.kind == Kind::Hinge) gb(B.offset) += B.axis.dot(gw);
    else gb.segment<3>(B.offset) += gw;
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
  for (int t : touching_) {
    const Eigen::Map<const Mat12> K(element.data() + t * 144);
    for (int c = 0; c < 4; ++c) {
      const int vc = model_.tets(t, c), bc = layout_.vertex_bone(vc);
      if (bc < 0) continue;
      const Bone& Bc = bones_[bc];
      const auto Jc = jacobian(Bc, x.row(vc).transpose() - poses[bc].p);
      for (int a = 0; a < 4; ++a) {
        const int va = model_.tets(t, a);
        const Mat3 Kac = K.block<3, 3>(3 * a, 3 * c);
        if (layout_.free_index(va) >= 0) {
          Hsb.block(3 * layout_.free_index(va), Bc.offset, 3, Bc.dofs) += Kac * Jc;
        } else if (layout_.vertex_bone(va) >= 0) {
          const int ba = layout_.vertex_bone(va);
          const Bone& Ba = bones_[ba];
          Hbb.block(Ba.offset, Bc.offset, Ba.dofs, Bc.dofs) +=
              jacobian(Ba, x.row(va).transpose() - poses[ba].p).transpose() * Kac * Jc;
        }
      }
    }
  }
  const Eigen::VectorXd& k = model_.bone_stiffness;
  for (size_t b = 0; b < bones_.size(); ++b) {
    const Bone& B = bones_[b];
    Mat3 G = Mat3::Zero();
    for (int v : B.vertices) {
      const Vec3 r = x.row(v).transpose() - poses[b].p, fv = f.row(v).transpose();
      G += 0.5 * (fv * r.transpose() + r * fv.transpose()) - fv.dot(r) * Mat3::Identity();
    }
    if (static_cast<Eigen::Index>(b) < k.size()) G += joint_spring::expmap_hessian(poses[b].R, k(b));
    if (!exact) {  // filtered Newton: clamp the rotation term's negative curvature
      Eigen::SelfAdjointEigenSolver<Mat3> es(G);
      G = es.eigenvectors() * es.eigenvalues().cwiseMax(0.0).asDiagonal() * es.eigenvectors().transpose();
    }
    if (B.kind == Kind::Hinge) Hbb(B.offset, B.offset) += B.axis.dot(G * B.axis);
    else Hbb.block<3, 3>(B.offset, B.offset) += G;
  }
}

bool RigidBones::solve_schur(const Eigen::MatrixXd& S, const Eigen::VectorXd& rb, bool exact, Eigen::VectorXd& db,
                             std::vector<NeutralMode>& neutral) const {
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
    Vec3 axis = B.kind == Kind::Hinge ? B.axis : Vec3(vi.segment<3>(B.offset).normalized());
    if (B.kind == Kind::Free && vi.segment<3>(B.offset).norm() < vi.segment<3>(B.offset + 3).norm())
      axis = vi.segment<3>(B.offset + 3).normalized();  // free to slide, not turn
    neutral.push_back({best, axis});
  }
  return true;
}

}  // namespace emu
