#include "emu/solvers/fem_solver.h"

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "emu/energy/material.h"

namespace emu {
namespace {
using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}
double bbox_diagonal(const Eigen::MatrixX3d& X) {
  return (X.colwise().maxCoeff() - X.colwise().minCoeff()).norm();
}
Mat3 hat(const Vec3& w) {
  Mat3 W;
  W << 0, -w(2), w(1), w(2), 0, -w(0), -w(1), w(0), 0;
  return W;
}
// exp(w^) by Rodrigues' formula.
Mat3 rotation_exp(const Vec3& w) {
  const double th = w.norm();
  const Mat3 W = hat(w);
  if (th < 1e-8) return Mat3::Identity() + W + 0.5 * W * W;
  return Mat3::Identity() + std::sin(th) / th * W + (1 - std::cos(th)) / (th * th) * W * W;
}
// Rotation R minimising sum |R (X_i - Xc) - (Y_i - Yc)|^2 (Kabsch).
Mat3 best_rotation(const Eigen::MatrixX3d& X, const Eigen::MatrixX3d& Y) {
  const Eigen::RowVector3d xc = X.colwise().mean(), yc = Y.colwise().mean();
  const Mat3 H = (X.rowwise() - xc).transpose() * (Y.rowwise() - yc);
  Eigen::JacobiSVD<Mat3> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 D = Mat3::Identity();
  if ((svd.matrixV() * svd.matrixU().transpose()).determinant() < 0) D(2, 2) = -1;
  return svd.matrixV() * D * svd.matrixU().transpose();
}
// Smallest rotation taking unit vector a to unit vector b.
Mat3 rotation_between(const Vec3& a, const Vec3& b) {
  const Vec3 v = a.cross(b);
  const double c = a.dot(b), s = v.norm();
  if (s < 1e-14) {
    if (c > 0) return Mat3::Identity();
    Vec3 perp = a.unitOrthogonal();
    return rotation_exp(M_PI * perp);
  }
  return rotation_exp(std::atan2(s, c) / s * v);
}

enum class BoneKind { Free, Ball, Hinge };

// One rigid bone's state and its Newton unknowns.
struct RigidBone {
  BoneKind kind = BoneKind::Free;
  int offset = 0, dofs = 6;
  int axis_end = -1;              // hinge: the anchor that spans the axis with the pivot
  Vec3 P = Vec3::Zero();          // rest pivot
  Mat3 R = Mat3::Identity();
  Vec3 p = Vec3::Zero();          // current pivot
  std::vector<int> vertices;      // non-pinned vertices placed by the bone
  Vec3 axis_current = Vec3::UnitX();
  /// 3 x dofs Jacobian of a vertex at current offset r = x - p.
  Eigen::Matrix<double, 3, Eigen::Dynamic> jacobian(const Vec3& r) const {
    Eigen::Matrix<double, 3, Eigen::Dynamic> J(3, dofs);
    if (kind == BoneKind::Hinge) {
      J.col(0) = axis_current.cross(r);
    } else {
      J.leftCols<3>() = -hat(r);
      if (kind == BoneKind::Free) J.rightCols<3>().setIdentity();
    }
    return J;
  }
  /// The rotation vector and translation of a Newton increment.
  void increment(const Eigen::VectorXd& db, double s, Vec3& w, Vec3& t) const {
    t.setZero();
    if (kind == BoneKind::Hinge) {
      w = s * db(offset) * axis_current;
    } else {
      w = s * db.segment<3>(offset);
      if (kind == BoneKind::Free) t = s * db.segment<3>(offset + 3);
    }
  }
};
}  // namespace

FemSolver::FemSolver(const Model& model, const SolverOptions& options)
    : model_((model.validate(), model)),
      disc_(model_),
      options_(options),
      pattern_(model_.tets, disc_.free_index, disc_.num_free, 3) {
  const auto t0 = Clock::now();
  for (const JointPoint& j : disc_.joints)
    if (j.other >= 0)
      throw std::invalid_argument("the FEM solver does not support joints between two movable bones yet (bones " +
                                  std::to_string(j.bone) + " and " + std::to_string(j.other) +
                                  "); use method='emu' or fix one bone");
  for (Eigen::Index t = 0; t < model_.tets.rows() && disc_.num_bones; ++t) {
    if (disc_.is_bone_tet(t)) continue;
    for (int a = 0; a < 4; ++a)
      if (disc_.vertex_bone(model_.tets(t, a)) >= 0) {
        bone_touching_.push_back(static_cast<int>(t));
        break;
      }
  }
  factor_.analyze(pattern_.rows(), pattern_.col_ptr().data(), pattern_.row_index().data());
  const Eigen::Index m = model_.tets.rows();
  element_.resize(m * 144);
  values_.resize(pattern_.nnz());
  corner_.resize(m * 12);
  tet_energy_.resize(m);
  setup_seconds_ = seconds_since(t0);
}

double FemSolver::energy_with(const Eigen::MatrixX3d& x, const Eigen::VectorXd& act,
                              const Eigen::Vector3d& grav) const {
  const Eigen::Index m = model_.tets.rows();
  const auto& geo = disc_.geometry;
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    if (disc_.is_bone_tet(t)) {  // rigid: no elastic energy
      tet_energy_[t] = 0.0;
      continue;
    }
    const TetMaterial mat{model_.mu(t), model_.lambda(t), act(t), model_.fiber.row(t).transpose()};
    tet_energy_[t] = geo.volume(t) * material_energy(mat, deformation_gradient(geo.grad[t], x, model_.tets, t));
  }
  double E = 0;
  for (Eigen::Index t = 0; t < m; ++t) E += tet_energy_[t];  // fixed order: reproducible
  if (grav.squaredNorm() > 0) E -= (disc_.lumped_mass.transpose() * x).dot(grav.transpose());
  return E;
}

void FemSolver::free_gradient(const LoadCase& load, const Eigen::MatrixX3d& x,
                              const Eigen::VectorXd& act, Eigen::VectorXd& g) const {
  const Eigen::Index m = model_.tets.rows();
  const auto& geo = disc_.geometry;
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    if (disc_.is_bone_tet(t)) {
      Eigen::Map<Vec12>(corner_.data() + t * 12).setZero();
      continue;
    }
    const TetMaterial mat{model_.mu(t), model_.lambda(t), act(t), model_.fiber.row(t).transpose()};
    const Mat3 P = material_stress(mat, deformation_gradient(geo.grad[t], x, model_.tets, t));
    Eigen::Map<Vec12>(corner_.data() + t * 12) = geo.volume(t) * corner_vectors(geo.grad[t], P);
  }
  g.resize(disc_.num_free * 3);
  pattern_.gather(corner_.data(), 3, g.data());
  if (load.gravity.squaredNorm() > 0)
    for (Eigen::Index v = 0; v < model_.rest.rows(); ++v)
      if (disc_.free_index(v) >= 0) g.segment<3>(3 * disc_.free_index(v)) -= disc_.lumped_mass(v) * load.gravity;
}

void FemSolver::assemble_hessian(const Eigen::MatrixX3d& x, const Eigen::VectorXd& act, bool exact) {
  const EigenFilter filter = options_.eigen_filter == 1 ? EigenFilter::Abs : EigenFilter::Clamp;
  const Eigen::Index m = model_.tets.rows();
  const auto& geo = disc_.geometry;
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    if (disc_.is_bone_tet(t)) {
      Eigen::Map<Mat12>(element_.data() + t * 144).setZero();
      continue;
    }
    const TetMaterial mat{model_.mu(t), model_.lambda(t), act(t), model_.fiber.row(t).transpose()};
    const Mat3 F = deformation_gradient(geo.grad[t], x, model_.tets, t);
    const Mat9 H = exact ? material_hessian(mat, F) : material_hessian_psd(mat, F, filter);
    Eigen::Map<Mat12>(element_.data() + t * 144) = geo.volume(t) * position_hessian(geo.grad[t], H);
  }
  pattern_.assemble(element_.data(), values_.data());
}

void FemSolver::vertex_forces(const Eigen::Vector3d& grav, Eigen::MatrixX3d& f) const {
  f = Eigen::MatrixX3d::Zero(model_.rest.rows(), 3);
  for (int t : bone_touching_)
    for (int a = 0; a < 4; ++a) {
      const int v = model_.tets(t, a);
      if (disc_.vertex_bone(v) >= 0) f.row(v) += Eigen::Map<const Vec3>(corner_.data() + t * 12 + 3 * a).transpose();
    }
  if (grav.squaredNorm() > 0)
    for (Eigen::Index v = 0; v < f.rows(); ++v)
      if (disc_.vertex_bone(v) >= 0) f.row(v) -= disc_.lumped_mass(v) * grav.transpose();
}

double FemSolver::energy(const LoadCase& load, const Eigen::MatrixX3d& x) const {
  validate_load(model_, load);
  return energy_with(x, tet_activation(model_, load), load.gravity);
}

Eigen::MatrixX3d FemSolver::gradient(const LoadCase& load, const Eigen::MatrixX3d& x) const {
  validate_load(model_, load);
  Eigen::VectorXd g;
  free_gradient(load, x, tet_activation(model_, load), g);
  Eigen::MatrixX3d out = Eigen::MatrixX3d::Zero(x.rows(), 3);
  for (Eigen::Index v = 0; v < x.rows(); ++v)
    if (disc_.free_index(v) >= 0) out.row(v) = g.segment<3>(3 * disc_.free_index(v)).transpose();
  return out;
}

SolveResult FemSolver::solve(const LoadCase& load, const Eigen::MatrixX3d* initial) {
  validate_load(model_, load);
  const auto t0 = Clock::now();
  const Eigen::VectorXd act = tet_activation(model_, load);
  SolveResult res;
  Eigen::MatrixX3d x = pinned_positions(model_, load);
  if (initial) {
    if (initial->rows() != x.rows() || !initial->allFinite())
      throw std::invalid_argument("initial positions must be finite and #V by 3");
    for (Eigen::Index v = 0; v < x.rows(); ++v)
      if (disc_.free_index(v) >= 0) x.row(v) = initial->row(v);
  }
  // Rigid bones: kind from their anchors, pose from the start positions.
  const int nb = disc_.num_bones;
  const double diag = bbox_diagonal(model_.rest);
  std::vector<RigidBone> bones(nb);
  // Anchors: (rest point, target) of every joint point of a bone.
  std::vector<std::vector<std::pair<Vec3, Vec3>>> anchors(nb);
  for (const JointPoint& j : disc_.joints) {
    Vec3 target = j.rest;
    if (j.vertex >= 0) target = x.row(j.vertex).transpose();
    else if (load.joint_targets.rows()) target = load.joint_targets.row(j.declared).transpose();
    anchors[j.bone].push_back({j.rest, target});
  }
  for (Eigen::Index v = 0; v < x.rows(); ++v)
    if (disc_.vertex_bone(v) >= 0) bones[disc_.vertex_bone(v)].vertices.push_back(static_cast<int>(v));
  int nd = 0;
  for (int b = 0; b < nb; ++b) {
    RigidBone& B = bones[b];
    const auto& an = anchors[b];
    if (an.empty()) {
      B.kind = BoneKind::Free;
      B.dofs = 6;
      B.P = disc_.bone_center.row(b).transpose();
    } else {
      const Vec3 X0 = an[0].first;
      for (size_t i = 1; i < an.size(); ++i)
        if (B.axis_end < 0 && (an[i].first - X0).norm() > 1e-9 * diag) B.axis_end = static_cast<int>(i);
      B.kind = B.axis_end < 0 ? BoneKind::Ball : BoneKind::Hinge;
      B.dofs = B.axis_end < 0 ? 3 : 1;
      if (B.axis_end >= 0) {
        const Vec3 a = (an[B.axis_end].first - X0).normalized();
        for (const auto& pt : an) {
          const Vec3 r = pt.first - X0;
          if ((r - r.dot(a) * a).norm() > 1e-6 * diag)
            throw std::invalid_argument("movable bone " + std::to_string(b) +
                                        " is welded: its joints with pinned vertices or fixed bones are not on "
                                        "one line; fix the bone instead");
        }
      }
      B.P = X0;
    }
    B.offset = nd;
    nd += B.dofs;
    // Pose: best rigid fit of the start positions (identity at rest), then the anchors' targets.
    Eigen::MatrixX3d Xb(B.vertices.size(), 3), Yb(B.vertices.size(), 3);
    for (size_t i = 0; i < B.vertices.size(); ++i) {
      Xb.row(i) = model_.rest.row(B.vertices[i]);
      Yb.row(i) = (initial ? *initial : model_.rest).row(B.vertices[i]);
    }
    B.R = initial ? best_rotation(Xb, Yb) : Mat3::Identity();
    if (B.kind == BoneKind::Free) {
      B.p = Yb.colwise().mean().transpose() - B.R * (Xb.colwise().mean().transpose() - B.P);
    } else {
      const auto& an = anchors[b];
      B.p = an[0].second;
      if (B.kind == BoneKind::Hinge) {
        const Vec3 rest_axis = an[B.axis_end].first - an[0].first;
        const Vec3 target = an[B.axis_end].second - an[0].second;
        if (std::abs(target.norm() - rest_axis.norm()) > 1e-6 * rest_axis.norm())
          throw std::invalid_argument("the hinge of movable bone " + std::to_string(b) +
                                      " is stretched by its pinned vertices' targets (move them rigidly)");
        B.R = rotation_between((B.R * rest_axis).normalized(), target.normalized()) * B.R;
        B.axis_current = target.normalized();
      }
    }
  }
  auto place_bones = [&](const std::vector<RigidBone>& bs, Eigen::MatrixX3d& out) {
    for (const RigidBone& B : bs)
      for (int v : B.vertices) out.row(v) = (B.R * (model_.rest.row(v).transpose() - B.P) + B.p).transpose();
  };
  place_bones(bones, x);
  const int nf = disc_.num_free;
  auto scatter = [&](const Eigen::VectorXd& d, double s, Eigen::MatrixX3d& out) {
    for (Eigen::Index v = 0; v < out.rows(); ++v)
      if (disc_.free_index(v) >= 0) out.row(v) += s * d.segment<3>(3 * disc_.free_index(v)).transpose();
  };
  // Bones moved along a Newton increment db by step s (exponential map).
  auto moved = [&](const Eigen::VectorXd& db, double s) {
    std::vector<RigidBone> out = bones;
    for (RigidBone& B : out) {
      Vec3 w, t;
      B.increment(db, s, w, t);
      B.R = rotation_exp(w) * B.R;
      B.p += t;
    }
    return out;
  };
  const Eigen::VectorXd& kb = model_.bone_stiffness;  // passive joint springs, if any
  // Reduced gradient: soft rows then bone rows (torques, forces).
  Eigen::VectorXd gs, gb(nd);
  Eigen::MatrixX3d fv;
  auto reduced_gradient = [&](const Eigen::MatrixX3d& xx, const std::vector<RigidBone>& bs) {
    free_gradient(load, xx, act, gs);
    if (!nd) return;
    vertex_forces(load.gravity, fv);
    gb.setZero();
    for (const RigidBone& B : bs)
      for (int v : B.vertices)
        gb.segment(B.offset, B.dofs) += B.jacobian((xx.row(v).transpose() - B.p)).transpose() * fv.row(v).transpose();
    // spring: d/dw of -k/2 tr(exp(w^) R) at w = 0 is k/2 (R32 - R23, R13 - R31, R21 - R12)
    for (int b = 0; b < kb.size(); ++b) {
      const RigidBone& B = bs[b];
      const Mat3& R = B.R;
      const Vec3 gw = 0.5 * kb(b) * Vec3(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1));
      if (B.kind == BoneKind::Hinge) gb(B.offset) += B.axis_current.dot(gw);
      else gb.segment<3>(B.offset) += gw;
    }
  };
  // Torques are scaled by the bounding-box diagonal in the reported norm (units of force).
  auto grad_norm = [&](const std::vector<RigidBone>& bs) {
    double n2 = gs.squaredNorm();
    for (const RigidBone& B : bs)
      for (int i = 0; i < B.dofs; ++i) {
        const double scale = (B.kind == BoneKind::Free && i >= 3) ? 1.0 : 1.0 / diag;
        n2 += std::pow(gb(B.offset + i) * scale, 2);
      }
    return std::sqrt(n2);
  };
  // Passive joint springs k/2 (3 - tr R) (model.bone_stiffness).
  auto spring_energy = [&](const std::vector<RigidBone>& bs) {
    double e = 0;
    for (int b = 0; b < kb.size(); ++b) e += 0.5 * kb(b) * (3.0 - bs[b].R.trace());
    return e;
  };
  double E = energy_with(x, act, load.gravity) + spring_energy(bones);
  reduced_gradient(x, bones);
  // Round-off in P(F) scales with the largest modulus (lambda at nu near 0.5).
  double force_scale = 0;
  for (Eigen::Index t = 0; t < model_.tets.rows(); ++t)
    if (!disc_.is_bone_tet(t)) force_scale += disc_.geometry.volume(t) * (model_.mu(t) + model_.lambda(t) + act(t));
  force_scale /= diag;
  Convergence conv{options_.rtol_grad, options_.rtol_energy, E, grad_norm(bones), 1e-13 * force_scale};
  res.grad_norm0 = conv.g0;
  res.history.push_back({0, E, conv.g0, 0.0, seconds_since(t0), 0, 0});
  res.status = "max iterations reached";
  if (conv.initial()) {
    res.converged = true;
    res.status = "converged: initial state is in equilibrium";
  }
  Eigen::VectorXd ds(nf * 3), db(nd), y(nf * 3);
  Eigen::MatrixXd Hsb(nf * 3, nd), Wsb(nf * 3, nd), Hbb(nd, nd);
  Eigen::MatrixX3d trial(x.rows(), 3);
  std::vector<RigidBone> trial_bones;
  std::vector<std::pair<int, Vec3>> neutral, last_neutral;  // neutral modes of the current / last step
  // Newton direction from the assembled soft block and the bone border.
  // Returns false if the matrix is not positive definite.
  auto newton_direction = [&](bool exact) {
    if (!factor_.factorize(values_.data())) return false;
    factor_.solve(gs.data(), y.data(), 1);
    if (!nd) {
      ds = -y;
      return true;
    }
    // Border: H_sb = sum K_ac J_c, H_bb = sum J_a^T K_ac J_c + rotation term.
    Hsb.setZero();
    Hbb.setZero();
    for (int t : bone_touching_) {
      const Eigen::Map<const Mat12> K(element_.data() + t * 144);
      for (int c = 0; c < 4; ++c) {
        const int vc = model_.tets(t, c), bc = disc_.vertex_bone(vc);
        if (bc < 0) continue;
        const RigidBone& Bc = bones[bc];
        const auto Jc = Bc.jacobian(x.row(vc).transpose() - Bc.p);
        for (int a = 0; a < 4; ++a) {
          const int va = model_.tets(t, a);
          const Mat3 Kac = K.block<3, 3>(3 * a, 3 * c);
          if (disc_.free_index(va) >= 0) {
            Hsb.block(3 * disc_.free_index(va), Bc.offset, 3, Bc.dofs) += Kac * Jc;
          } else if (disc_.vertex_bone(va) >= 0) {
            const RigidBone& Ba = bones[disc_.vertex_bone(va)];
            Hbb.block(Ba.offset, Bc.offset, Ba.dofs, Bc.dofs) +=
                Ba.jacobian(x.row(va).transpose() - Ba.p).transpose() * Kac * Jc;
          }
        }
      }
    }
    for (int bi = 0; bi < nb; ++bi) {
      const RigidBone& B = bones[bi];
      Mat3 G = Mat3::Zero();
      for (int v : B.vertices) {
        const Vec3 r = x.row(v).transpose() - B.p, f = fv.row(v).transpose();
        G += 0.5 * (f * r.transpose() + r * f.transpose()) - f.dot(r) * Mat3::Identity();
      }
      if (bi < kb.size()) {  // spring: k/2 (tr R I - sym R)
        const Mat3& R = B.R;
        G += 0.5 * kb(bi) * (R.trace() * Mat3::Identity() - 0.5 * (R + R.transpose()));
      }
      if (!exact) {  // filtered Newton: clamp the rotation term's negative curvature
        Eigen::SelfAdjointEigenSolver<Mat3> es(G);
        G = es.eigenvectors() * es.eigenvalues().cwiseMax(0.0).asDiagonal() * es.eigenvectors().transpose();
      }
      if (B.kind == BoneKind::Hinge)
        Hbb(B.offset, B.offset) += B.axis_current.dot(G * B.axis_current);
      else
        Hbb.block<3, 3>(B.offset, B.offset) += G;
    }
    factor_.solve(Hsb.data(), Wsb.data(), nd);
    Eigen::MatrixXd S = Hbb - Hsb.transpose() * Wsb;
    S = 0.5 * (S + S.transpose()).eval();
    const Eigen::VectorXd rb = -gb + Hsb.transpose() * y;
    Eigen::LLT<Eigen::MatrixXd> llt(S);
    if (llt.info() == Eigen::Success &&
        llt.matrixLLT().diagonal().minCoeff() > 1e-6 * std::sqrt(S.diagonal().maxCoeff())) {
      db = llt.solve(rb);
    } else {
      if (exact) return false;
      // A bone direction nothing resists (a neutral mode): S is singular there.
      // Step with its pseudo-inverse (that direction is left alone) and say which.
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(S);
      const Eigen::VectorXd& lam = es.eigenvalues();
      const double lmax = lam.cwiseAbs().maxCoeff();
      db.setZero();
      neutral.clear();
      for (int i = 0; i < nd; ++i) {
        const Eigen::VectorXd vi = es.eigenvectors().col(i);
        if (lam(i) > 1e-10 * lmax) {
          db += vi * (vi.dot(rb) / lam(i));
          continue;
        }
        if (lam(i) < -1e-10 * lmax) return false;  // filtered S is PSD up to round-off
        int best = 0;
        for (int b = 1; b < nb; ++b)
          if (vi.segment(bones[b].offset, bones[b].dofs).norm() >
              vi.segment(bones[best].offset, bones[best].dofs).norm())
            best = b;
        const RigidBone& B = bones[best];
        Vec3 axis = B.kind == BoneKind::Hinge ? B.axis_current : Vec3(vi.segment<3>(B.offset).normalized());
        if (B.kind == BoneKind::Free && vi.segment<3>(B.offset).norm() < vi.segment<3>(B.offset + 3).norm())
          axis = vi.segment<3>(B.offset + 3).normalized();  // free to slide, not turn
        neutral.push_back({best, axis});
      }
    }
    ds = -y - Wsb * db;
    return true;
  };
  bool last_exact_ok = true;
  for (int it = 1; !res.converged && it <= options_.max_iterations; ++it) {
    if (options_.interrupted && options_.interrupted()) {
      res.status = "interrupted";
      break;
    }
    // Newton with the true Hessian where it is definite (near a stable
    // equilibrium). A failed attempt costs a factorisation, so after one it is
    // retried only once the iteration is in the Newton regime (last step full).
    const bool try_exact = options_.exact_when_definite &&
                           (last_exact_ok || res.history.back().step == 1.0);
    bool have = false;
    if (try_exact) {
      assemble_hessian(x, act, true);
      if (newton_direction(true) && gs.dot(ds) + (nd ? gb.dot(db) : 0.0) < 0) {
        last_exact_ok = true;
        have = true;
      } else {
        ++res.exact_attempts_failed;
        last_exact_ok = false;
      }
    }
    if (!have) {
      ++res.filtered_steps;
      assemble_hessian(x, act, false);
      bool ok = newton_direction(false);
      // Projected element Hessians make H PSD; a pinned scene makes it definite.
      // Roundoff can still break the Cholesky: shift the diagonal and retry.
      double shift = 0;
      for (int retry = 0; !ok && retry < 8; ++retry) {
        double dmax = 0;
        for (int j = 0; j < pattern_.rows(); ++j) dmax = std::max(dmax, values_[pattern_.col_ptr()[j + 1] - 1]);
        const double add = (shift == 0 ? 1e-10 * dmax : shift * 9.0);
        for (int j = 0; j < pattern_.rows(); ++j) values_[pattern_.col_ptr()[j + 1] - 1] += add;
        shift += add;
        ok = newton_direction(false);
      }
      if (!ok) {
        res.status = "Newton matrix is not positive definite even after regularisation";
        break;
      }
    }
    const double slope = gs.dot(ds) + (nd ? gb.dot(db) : 0.0);
    last_neutral = have ? std::vector<std::pair<int, Vec3>>() : neutral;
    neutral.clear();
    if (!(slope < 0)) {
      res.status = "Newton direction is not a descent direction";
      break;
    }
    auto trial_energy = [&](double s) {
      trial = x;
      scatter(ds, s, trial);
      if (nd) {
        trial_bones = moved(db, s);
        place_bones(trial_bones, trial);
      }
      return energy_with(trial, act, load.gravity) + spring_energy(nd ? trial_bones : bones);
    };
    auto ls = armijo_backtracking(trial_energy, E, slope, options_);
    if (!ls.success) {
      const double E1 = trial_energy(1.0);
      const double gn_old = grad_norm(bones);
      const Eigen::VectorXd gs_old = gs, gb_old = gb;
      reduced_gradient(trial, nd ? trial_bones : bones);
      const double g1 = grad_norm(nd ? trial_bones : bones);
      gs = gs_old;
      gb = gb_old;
      if (accept_at_roundoff(E1, g1, E, gn_old, conv.E0)) {
        ls.success = true;
        ls.step = 1.0;
        ls.energy = E1;
      } else {
        res.status = "stalled: no step along the Newton direction decreases the energy or the gradient "
                     "(round-off level reached; loosen rtol_grad / rtol_energy)";
        break;
      }
    }
    scatter(ds, ls.step, x);
    if (nd) {
      bones = moved(db, ls.step);
      place_bones(bones, x);
    }
    const double E_prev = E;
    E = ls.energy;
    reduced_gradient(x, bones);
    const double gn = grad_norm(bones);
    res.iterations = it;
    res.history.push_back({it, E, gn, ls.step, seconds_since(t0), 0, ls.backtracks});
    if (conv.test(E_prev, E, gn)) {
      res.converged = true;
      res.status = "converged";
    }
  }
  res.neutral_axes.resize(last_neutral.size(), 3);
  for (size_t i = 0; i < last_neutral.size(); ++i) {
    res.neutral_bones.push_back(last_neutral[i].first);
    res.neutral_axes.row(i) = last_neutral[i].second.transpose();
  }
  res.positions = x;
  res.energy = E;
  res.grad_norm = res.history.back().grad_norm;
  res.rel_energy_change = conv.rel_energy_change;
  res.time_s = seconds_since(t0);
  return res;
}

}  // namespace emu
