#include "emu/solvers/emu/acap.h"

#include <stdexcept>
#include <string>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

namespace emu {

void deformation_gradients(const UnknownLayout& layout, const Eigen::MatrixX4i& T,
                           const Eigen::MatrixX3d& x, Mat9X& out) {
  const Eigen::Index m = T.rows();
  out.resize(9, m);
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) out.col(t) = flatten(deformation_gradient(layout.geometry.grad[t], x, T, t));
}

void expand_unknowns(const UnknownLayout& layout, const Mat9X& U, Mat9X& out) {
  const Eigen::Index m = layout.tet_unknown.size();
  out.resize(9, m);
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) out.col(t) = U.col(layout.tet_unknown(t));
}

const Mat9X& per_tet_view(const UnknownLayout& layout, const Mat9X& U, Mat9X& buf) {
  if (layout.num_bones == 0) return U;
  expand_unknowns(layout, U, buf);
  return buf;
}

void reduce_to_unknowns(const UnknownLayout& layout, Mat9X& per_tet, Mat9X& out) {
  if (layout.num_bones == 0) {
    out.swap(per_tet);
    return;
  }
  const long nu = layout.num_unknowns;
  out.resize(9, nu);
#pragma omp parallel for schedule(dynamic, 256)
  for (long u = 0; u < nu; ++u) {
    Vec9 s = Vec9::Zero();
    for (int i = layout.unknown_ptr[u]; i < layout.unknown_ptr[u + 1]; ++i) s += per_tet.col(layout.unknown_tets[i]);
    out.col(u) = s;
  }
}

namespace {
// Rows from which the ACAP factor tries METIS beside AMD (see the constructor).
constexpr int kAcapMetisRows = 10000;

Eigen::Vector4d phi_at(const UnknownLayout& layout, const Eigen::Vector3d& X, int b) {
  Eigen::Vector4d p;
  p.head<3>() = X - layout.bone_center.row(b).transpose();
  p(3) = 1.0;
  return p;
}
Eigen::Vector4d phi_of(const Model& model, const UnknownLayout& layout, int v, int b) {
  return phi_at(layout, model.rest.row(v).transpose(), b);
}
}  // namespace

AcapOperator::AcapOperator(const Model& model, const UnknownLayout& layout, const Eigen::VectorXd* weight_volume,
                           const AcapOperator* pattern_of, bool single_precision,
                           const Eigen::VectorXd* free_diagonal)
    : rounded_(single_precision), model_(model), layout_(layout),
      pattern_(pattern_of ? pattern_of->pattern_
                          : std::make_shared<const BlockPattern>(model.tets, layout.free_index, layout.num_free, 1)) {
  const Eigen::Index m = model.tets.rows();
  ns_ = layout.num_free;
  nq_ = 4 * layout.num_bones;
  if (ns_ == 0)
    throw std::invalid_argument("the model has no free soft vertex: every vertex is pinned or on a bone");
  if (weight_volume && weight_volume->size() != m)
    throw std::invalid_argument("AcapOperator: one weight per tet expected");
  wv_ = weight_volume ? *weight_volume : Eigen::VectorXd(model.acap_weight.cwiseProduct(layout.geometry.volume));
  std::vector<double> element(m * 16);
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    const ShapeGrads& b = layout.geometry.grad[t];
    Eigen::Map<Eigen::Matrix4d>(element.data() + t * 16) = wv_(t) * b * b.transpose();
  }
  std::vector<double> values(pattern_->nnz());
  pattern_->assemble(element.data(), values.data());
  if (free_diagonal) {
    if (free_diagonal->size() != ns_) throw std::invalid_argument("AcapOperator: one diagonal value per free vertex expected");
    // the upper triangle by columns: each column's diagonal entry is its last
    const auto& cp = pattern_->col_ptr();
    const auto& ri = pattern_->row_index();
    for (int j = 0; j < ns_; ++j) {
      if (ri[cp[j + 1] - 1] != j) throw std::logic_error("AcapOperator: a column's last entry is not its diagonal");
      values[cp[j + 1] - 1] += (*free_diagonal)(j);
    }
  }
  // METIS where it pays (docs/DESIGN.md, "Orderings"): CHOLMOD's default
  // keeps AMD for the ACAP matrix of a compact 3D mesh at any size, while
  // METIS fills less on large meshes; below kAcapMetisRows its gain is too
  // small to pay for its analysis.
  factor_.set_metis_from_rows(kAcapMetisRows);
  if (pattern_of) factor_.analyze_like(pattern_of->factor_);
  else factor_.analyze(pattern_->rows(), pattern_->col_ptr().data(), pattern_->row_index().data());
  if (!factor_.factorize(values.data()))
    throw std::invalid_argument(
        "the ACAP matrix is singular: some part of the mesh is not connected to a pinned vertex, "
        "fixed bone or movable bone; pin a vertex of every connected component");
  if (rounded_) factor_.keep_single_precision_copy();  // before setup_bones: its solves use it too
  corner_.resize(m * 12);
  rhs_rows_.resize(ns_, 3);
  if (nq_) setup_bones(pattern_of);
  // Factorised once, solved two or three times per CG iteration with 3
  // right-hand sides: the factor stays supernodal, solved by
  // supernodal_solve_in_place (CholmodFactor::solve), which beats CHOLMOD's
  // simplicial solve on small meshes as well (docs/DESIGN.md, "The cost of
  // an iteration").
}

void AcapOperator::setup_bones(const AcapOperator* same_model) {
  const auto& vb = layout_.vertex_bone;
  Eigen::Matrix<double, 4, Eigen::Dynamic> phi(4, vb.size());  // of each bone vertex
  for (Eigen::Index v = 0; v < vb.size(); ++v)
    if (vb(v) >= 0) phi.col(v) = phi_of(model_, layout_, static_cast<int>(v), vb(v));
  if (same_model) {
    // The tets' roles and the bone corners depend on the model alone, not
    // on the weights: ConstantSchur's S0 (and each new alpha's) copies them.
    is_rigid_ = same_model->is_rigid_;
    rigid_tets_ = same_model->rigid_tets_;
    rigid_tet_bone_ = same_model->rigid_tet_bone_;
    bone_tets_ = same_model->bone_tets_;
    bone_corner_ = same_model->bone_corner_;
    bone_corner_bone_ = same_model->bone_corner_bone_;
    bone_corner_phi_ = same_model->bone_corner_phi_;
  } else {
    classify_bone_tets(phi);
  }
  sum_rigid_tets();
  eliminate_soft_block(phi);
  setup_joint_rows();
}

void AcapOperator::classify_bone_tets(const Eigen::Matrix<double, 4, Eigen::Dynamic>& phi) {
  const Eigen::Index m = model_.tets.rows();
  const auto& vb = layout_.vertex_bone;
  is_rigid_.assign(m, 0);
  for (Eigen::Index t = 0; t < m; ++t) {
    bool touches = false;
    for (int a = 0; a < 4; ++a) touches |= vb(model_.tets(t, a)) >= 0;
    if (touches) bone_tets_.push_back(static_cast<int>(t));
    const int b = vb(model_.tets(t, 0));
    bool rigid = b >= 0;
    for (int a = 1; a < 4; ++a) rigid = rigid && vb(model_.tets(t, a)) == b;
    if (!rigid) continue;
    is_rigid_[t] = 1;
    rigid_tets_.push_back(static_cast<int>(t));
    rigid_tet_bone_.push_back(b);
  }
  for (Eigen::Index t = 0; t < m; ++t)
    for (int a = 0; a < 4; ++a) {
      const int v = model_.tets(t, a);
      if (vb(v) < 0 || is_rigid_[t]) continue;
      bone_corner_.push_back(static_cast<int>(t * 4 + a));
      bone_corner_bone_.push_back(vb(v));
    }
  bone_corner_phi_.resize(4, bone_corner_.size());
  for (size_t i = 0; i < bone_corner_.size(); ++i)
    bone_corner_phi_.col(i) = phi.col(model_.tets(bone_corner_[i] / 4, bone_corner_[i] % 4));
}

void AcapOperator::sum_rigid_tets() {
  rigid_own_wv_ = Eigen::VectorXd::Zero(layout_.num_bones);
  rigid_own_tets_.assign(layout_.num_bones, -1);
  rigid_other_tets_.clear();
  rigid_other_bone_.clear();
  for (size_t i = 0; i < rigid_tets_.size(); ++i) {
    const int t = rigid_tets_[i], b = rigid_tet_bone_[i];
    if (layout_.tet_unknown(t) == layout_.num_soft + b) {
      rigid_own_wv_(b) += wv_(t);
      rigid_own_tets_[b] = t;
    } else {
      rigid_other_tets_.push_back(t);
      rigid_other_bone_.push_back(b);
    }
  }
}

void AcapOperator::eliminate_soft_block(const Eigen::Matrix<double, 4, Eigen::Dynamic>& phi) {
  // Coupling L_sb and bone block L_bb from the element matrices w V b_a . b_c
  // of the tets touching a bone, each vertex's phi once; L_sb summed in rows
  // (a free vertex's four entries per bone side by side), then stored by
  // columns for the solve (the same sums in the same order).
  const auto& vb = layout_.vertex_bone;
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> Lsb_rows =
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>::Zero(ns_, nq_);
  Eigen::MatrixXd Lbb = Eigen::MatrixXd::Zero(nq_, nq_);
  for (const int t : bone_tets_) {
    const ShapeGrads& b = layout_.geometry.grad[t];
    for (int a = 0; a < 4; ++a) {
      const int va = model_.tets(t, a);
      for (int c = 0; c < 4; ++c) {
        const int vc = model_.tets(t, c);
        if (vb(vc) < 0) continue;
        const double e = wv_(t) * b.row(a).dot(b.row(c));
        const Eigen::Vector4d pc = phi.col(vc);
        if (layout_.free_index(va) >= 0) {
          Lsb_rows.block<1, 4>(layout_.free_index(va), 4 * vb(vc)) += e * pc.transpose();
        } else if (vb(va) >= 0) {
          Lbb.block<4, 4>(4 * vb(va), 4 * vb(vc)) += e * phi.col(va) * pc.transpose();
        }
      }
    }
  }
  const Eigen::MatrixXd Lsb = Lsb_rows;
  W_.resize(ns_, nq_);
  factor_.solve(Lsb.data(), W_.data(), nq_, rounded_);
  Sb_ = Lbb - Lsb.transpose() * W_;
  Sb_ = 0.5 * (Sb_ + Sb_.transpose()).eval();
}

void AcapOperator::setup_joint_rows() {
  const int nj = static_cast<int>(layout_.joints.size());
  J_ = Eigen::MatrixXd::Zero(nj, nq_);
  for (int r = 0; r < nj; ++r) {
    const JointPoint& j = layout_.joints[r];
    J_.block<1, 4>(r, 4 * j.bone) += phi_at(layout_, j.rest, j.bone).transpose();
    if (j.other >= 0) J_.block<1, 4>(r, 4 * j.other) -= phi_at(layout_, j.rest, j.other).transpose();
  }
  Eigen::MatrixXd V;
  rank_ = 0;
  if (nj) {
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(J_, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::VectorXd& s = svd.singularValues();
    while (rank_ < s.size() && s(rank_) > 1e-9 * s(0)) ++rank_;
    V = svd.matrixV();
    Jpinv_ = V.leftCols(rank_) * s.head(rank_).cwiseInverse().asDiagonal() *
             svd.matrixU().leftCols(rank_).transpose();
  } else {
    V = Eigen::MatrixXd::Identity(nq_, nq_);
    Jpinv_.resize(nq_, 0);
  }
  N_ = V.rightCols(nq_ - rank_);
  const Eigen::MatrixXd red = N_.transpose() * Sb_ * N_;
  if (red.rows()) {
    const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(red).eigenvalues();
    if (!(ev(0) > 1e-12 * ev(ev.size() - 1)))
      throw std::invalid_argument(
          "a movable bone cannot be placed: it is connected to no pinned vertex, fixed bone or soft "
          "tissue that fixes its position; attach it (a joint or a muscle) or fix it");
  }
  reduced_.compute(red);
}

Eigen::MatrixX3d AcapOperator::joint_targets(const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& declared) const {
  Eigen::MatrixX3d h = Eigen::MatrixX3d::Zero(layout_.joints.size(), 3);
  for (size_t r = 0; r < layout_.joints.size(); ++r) {
    const JointPoint& j = layout_.joints[r];
    if (j.other >= 0) continue;
    if (j.vertex >= 0) h.row(r) = x.row(j.vertex);
    else h.row(r) = declared.rows() ? Eigen::RowVector3d(declared.row(j.declared)) : Eigen::RowVector3d(j.rest.transpose());
  }
  return h;
}

void AcapOperator::solve_rounded(const Eigen::MatrixXd& R, Eigen::MatrixXd& Z) const {
  if (nq_) throw std::logic_error("AcapOperator::solve_rounded of an operator with movable bones");
  Z.resize(ns_, R.cols());
  factor_.solve(R.data(), Z.data(), static_cast<int>(R.cols()), true);
}

void AcapOperator::solve_with(const Eigen::MatrixXd& R, const Eigen::MatrixXd* h, Eigen::MatrixXd& Z) const {
  const int nc = static_cast<int>(R.cols());
  Z.resize(dofs(), nc);
  Eigen::MatrixXd y0(ns_, nc);
  Eigen::MatrixXd Rs = R.topRows(ns_);
  factor_.solve(Rs.data(), y0.data(), nc, rounded_);
  if (!nq_) {
    Z = y0;
    return;
  }
  // Bone problem in the null space of J: q = q_p + N w,
  // (N^T S_b N) w = N^T (r_b - W^T r_s - S_b q_p).
  const Eigen::MatrixXd rb = R.bottomRows(nq_) - W_.transpose() * Rs;
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(nq_, nc);
  if (h && rank_) q = Jpinv_ * (*h);
  if (N_.cols()) q += N_ * reduced_.solve(N_.transpose() * (rb - Sb_ * q));
  Z.topRows(ns_) = y0 - W_ * q;
  Z.bottomRows(nq_) = q;
}

namespace {
// Rigid tets (skip[t], empty without bones) are left out: apply_C_with adds their sums.
template <class TargetOf>
void corner_targets(const Eigen::VectorXd& wv, const UnknownLayout& layout, TargetOf&& target,
                    const std::vector<char>& skip, double* corner) {
  const Eigen::Index m = wv.size();
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    if (!skip.empty() && skip[t]) continue;
    const auto T = target(t);  // a map of the 9 doubles in place: no copy through the stack
    const ShapeGrads& b = layout.geometry.grad[t];
    for (int a = 0; a < 4; ++a) Eigen::Map<Vec3>(corner + t * 12 + 3 * a) = wv(t) * T * b.row(a).transpose();
  }
}
}  // namespace

template <class TargetOf>
void AcapOperator::apply_C_with(TargetOf&& target, Eigen::MatrixX3d& R, bool by_unknowns) const {
  corner_targets(wv_, layout_, target, is_rigid_, corner_.data());
  pattern_->gather(corner_.data(), 3, rhs_rows_.data());
  R.resize(dofs(), 3);
  R.topRows(ns_) = rhs_rows_;
  if (!nq_) return;
  R.bottomRows(nq_).setZero();
  for (size_t i = 0; i < bone_corner_.size(); ++i)  // fixed order: reproducible
    R.block<4, 3>(ns_ + 4 * bone_corner_bone_[i], 0).noalias() +=
        bone_corner_phi_.col(i) * Eigen::Map<const Vec3>(corner_.data() + 3 * bone_corner_[i]).transpose();
  if (by_unknowns)
    for (int b = 0; b < layout_.num_bones; ++b) {  // a bone's own rigid tets: (sum w V) T_b^T
      if (rigid_own_wv_(b) == 0) continue;
      const int t = rigid_own_tets_[b];  // any of them: they share the bone's unknown
      R.block<3, 3>(ns_ + 4 * b, 0).noalias() += rigid_own_wv_(b) * target(t).transpose();
    }
  // the other rigid tets (all of them unless by_unknowns): w V [T^T; 0] each (acap.h)
  const std::vector<int>& tets = by_unknowns ? rigid_other_tets_ : rigid_tets_;
  const std::vector<int>& bones = by_unknowns ? rigid_other_bone_ : rigid_tet_bone_;
  for (size_t i = 0; i < tets.size(); ++i)
    R.block<3, 3>(ns_ + 4 * bones[i], 0).noalias() += wv_(tets[i]) * target(tets[i]).transpose();
}

void AcapOperator::apply_C(const Mat9X& D, Eigen::MatrixX3d& R) const {
  apply_C_with([&](Eigen::Index t) { return Eigen::Map<const Mat3>(D.col(t).data()); }, R);
}

void AcapOperator::apply_C_of_unknowns(const Mat9X& U, Eigen::MatrixX3d& R) const {
  if (layout_.num_bones == 0) {  // one unknown per tet, in tet order
    apply_C(U, R);
    return;
  }
  apply_C_with([&](Eigen::Index t) { return Eigen::Map<const Mat3>(U.col(layout_.tet_unknown(t)).data()); }, R,
               true);
}

void AcapOperator::fit_of_unknowns(const Mat9X& U, Eigen::MatrixX3d& x) const {
  Eigen::MatrixX3d R;
  apply_C_of_unknowns(U, R);
  Eigen::MatrixXd Z;
  solve_with(R, nullptr, Z);
  expand(Eigen::MatrixX3d(Z), x);
}

void AcapOperator::fit(const Mat9X& F, const Mat9X* F_pinned, const Eigen::MatrixX3d* h, Eigen::MatrixX3d& x) const {
  // Normal equations: K z = C (F - F_t(x_pinned)), J q = h.
  Eigen::MatrixX3d R;
  if (F_pinned) {
    const Mat9X target = F - *F_pinned;
    apply_C(target, R);
  } else {
    apply_C(F, R);
  }
  Eigen::MatrixXd Z, hd;
  if (h) hd = *h;
  solve_with(R, h ? &hd : nullptr, Z);
  expand(Eigen::MatrixX3d(Z), x);
}

template <class M>
static void expand_impl(const Model& model, const UnknownLayout& layout, int ns, const M& Z, M& x) {
  const Eigen::Index n = x.rows();
  const int nc = static_cast<int>(Z.cols());
#pragma omp parallel for schedule(static)
  for (Eigen::Index v = 0; v < n; ++v) {
    if (layout.free_index(v) >= 0) {
      x.row(v) = Z.row(layout.free_index(v));
    } else if (layout.vertex_bone(v) >= 0) {
      const int b = layout.vertex_bone(v);
      x.row(v) = phi_of(model, layout, static_cast<int>(v), b).transpose() * Z.block(ns + 4 * b, 0, 4, nc);
    }
  }
}

void AcapOperator::expand(const Eigen::MatrixXd& Z, Eigen::MatrixXd& x) const {
  expand_impl(model_, layout_, ns_, Z, x);
}
void AcapOperator::expand(const Eigen::MatrixX3d& Z, Eigen::MatrixX3d& x) const {
  expand_impl(model_, layout_, ns_, Z, x);
}

void AcapOperator::apply_CT(const Eigen::MatrixX3d& u, Mat9X& out) const {
  Eigen::MatrixX3d x = Eigen::MatrixX3d::Zero(model_.rest.rows(), 3);
  expand(u, x);
  const Eigen::Index m = model_.tets.rows();
  out.resize(9, m);
  // F_t(x) scaled in the same pass (a CG iteration calls this once or twice)
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    if (!is_rigid_.empty() && is_rigid_[t]) {  // the linear part of its bone's map (acap.h)
      const int b = layout_.vertex_bone(model_.tets(t, 0));
      out.col(t) = flatten(Mat3(u.block<3, 3>(ns_ + 4 * b, 0).transpose())) * wv_(t);
      continue;
    }
    out.col(t) = flatten(deformation_gradient(layout_.geometry.grad[t], x, model_.tets, t)) * wv_(t);
  }
}

void AcapOperator::reduce_vertex(const Eigen::MatrixX3d& f, Eigen::MatrixX3d& R) const {
  R = Eigen::MatrixX3d::Zero(dofs(), 3);
  for (Eigen::Index v = 0; v < f.rows(); ++v) {
    if (layout_.free_index(v) >= 0) {
      R.row(layout_.free_index(v)) = f.row(v);
    } else if (layout_.vertex_bone(v) >= 0) {
      const int b = layout_.vertex_bone(v);
      R.block<4, 3>(ns_ + 4 * b, 0).noalias() += phi_of(model_, layout_, static_cast<int>(v), b) * f.row(v);
    }
  }
}

}  // namespace emu
