#include "emu/solvers/emu_solver.h"

#include <chrono>
#include <cmath>
#include <stdexcept>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <limits>

#include "emu/energy/material.h"

namespace emu {
namespace {
using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
double dot(const Mat9X& a, const Mat9X& b) { return a.cwiseProduct(b).sum(); }

// Nearest rotation (polar decomposition) of a 3x3 matrix near a rotation.
Mat3 nearest_rotation(const Mat3& M) {
  Eigen::JacobiSVD<Mat3> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) *= -1.0;
  return U * svd.matrixV().transpose();
}
}  // namespace

struct EmuSolver::Context {
  Eigen::VectorXd act;         // #T activation
  Eigen::MatrixX3d x_pinned;   // #V by 3: pinned rows at targets, other rows zero
  Mat9X F_pinned;              // F_t(x_pinned)
  Eigen::MatrixX3d h;          // joint targets
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();
  bool has_gravity = false;
  Mat9X F_gravity;             // F_t(L^-1 f): the load's share of the gradient
};

EmuSolver::EmuSolver(const Model& model, const SolverOptions& options, const EmuOptions& emu_options)
    : model_((model.validate(), model)), disc_(model_), options_(options), emu_(emu_options) {
  if (!(emu_.alpha > 0) || !std::isfinite(emu_.alpha)) throw std::invalid_argument("alpha must be positive and finite");
  if (emu_.modes < 0) throw std::invalid_argument("the number of modes must be >= 0");
  if (disc_.num_bones && emu_.step == EmuStep::NewtonKrylov && emu_.preconditioner == EmuPreconditioner::Schur)
    throw std::invalid_argument("the Schur-complement preconditioner does not handle movable bones; "
                                "use preconditioner='woodbury'");
  auto t0 = Clock::now();
  acap_ = std::make_unique<AcapOperator>(model_, disc_);
  factor_seconds_ = seconds_since(t0);
  t0 = Clock::now();
  // Modes only where the Woodbury approximation is used (section 7: leave out
  // what the solve does not need).
  const bool schur = emu_.step == EmuStep::NewtonKrylov && emu_.preconditioner == EmuPreconditioner::Schur;
  const int ks = schur ? 0 : (emu_.modes + 2) / 3;
  const Modes modes =
      acap_->has_bones()
          ? lowest_modes_of_inverse(acap_->dofs(),
                                    [&](const double* in, double* out) {
                                      Eigen::MatrixXd R = Eigen::Map<const Eigen::VectorXd>(in, acap_->dofs());
                                      Eigen::MatrixXd Z;
                                      acap_->solve(R, Z);
                                      Eigen::Map<Eigen::VectorXd>(out, acap_->dofs()) = Z.col(0);
                                    },
                                    ks, acap_->constraint_rank())
          : lowest_modes(acap_->factor(), std::min(ks, disc_.num_free));
  modes_seconds_ = seconds_since(t0);
  woodbury_ = std::make_unique<Woodbury>(model_, disc_, *acap_, modes, emu_.alpha);
  if (schur) {
    t0 = Clock::now();
    schur_ = std::make_unique<SchurPreconditioner>(model_, disc_, *acap_, emu_.alpha);
    factor_seconds_ += seconds_since(t0);
  }
  tet_energy_.resize(model_.tets.rows());
}

EmuSolver::Context EmuSolver::make_context(const LoadCase& load) const {
  validate_load(model_, load);
  Context c;
  c.act = tet_activation(model_, load);
  c.x_pinned = pinned_positions(model_, load);
  Eigen::MatrixX3d f = Eigen::MatrixX3d::Zero(model_.rest.rows(), 3);
  for (Eigen::Index v = 0; v < c.x_pinned.rows(); ++v)
    if (disc_.free_index(v) >= 0 || disc_.vertex_bone(v) >= 0) {
      c.x_pinned.row(v).setZero();
      f.row(v) = disc_.lumped_mass(v) * load.gravity.transpose();
    }
  deformation_gradients(disc_, model_.tets, c.x_pinned, c.F_pinned);
  c.h = acap_->joint_targets(pinned_positions(model_, load), load.joint_targets);
  c.gravity = load.gravity;
  c.has_gravity = load.gravity.squaredNorm() > 0;
  if (c.has_gravity) {
    // d W(x*(F)) / dF = C^T K_c^-1 S^T f: one constant solve per load.
    Eigen::MatrixX3d R;
    acap_->reduce_vertex(f, R);
    Eigen::MatrixXd Z;
    acap_->solve(Eigen::MatrixXd(R), Z);
    Eigen::MatrixX3d yfull = Eigen::MatrixX3d::Zero(model_.rest.rows(), 3);
    acap_->expand(Eigen::MatrixX3d(Z), yfull);
    deformation_gradients(disc_, model_.tets, yfull, c.F_gravity);
  }
  return c;
}

void EmuSolver::fit_into(const Context& c, const Mat9X& F, Eigen::MatrixX3d& x, Mat9X& Fx) const {
  Mat9X buf;
  x = c.x_pinned;
  acap_->fit(per_tet_view(disc_, F, buf), &c.F_pinned, &c.h, x);
  deformation_gradients(disc_, model_.tets, x, Fx);
}

void EmuSolver::fit_linear_into(const Mat9X& D, Eigen::MatrixX3d& dx, Mat9X& Fd) const {
  Mat9X buf;
  dx.setZero(model_.rest.rows(), 3);
  acap_->fit(per_tet_view(disc_, D, buf), nullptr, nullptr, dx);
  deformation_gradients(disc_, model_.tets, dx, Fd);
}

void EmuSolver::project_tangent(const Mat9X& F, Mat9X& v) const {
  for (int u = disc_.num_soft; u < disc_.num_unknowns; ++u) {
    const Mat3 R = unflatten(F.col(u));
    const Mat3 K = R.transpose() * unflatten(v.col(u));
    v.col(u) = flatten(Mat3(R * (0.5 * (K - K.transpose()))));
  }
}

void EmuSolver::retract(const Mat9X& F, const Mat9X& d, double s, Mat9X& out) const {
  out = F + s * d;
  for (int u = disc_.num_soft; u < disc_.num_unknowns; ++u) out.col(u) = flatten(nearest_rotation(unflatten(out.col(u))));
}

void EmuSolver::riemannian_product(const std::vector<Mat9>& A, const Mat9X& F, const Mat9X& g, const Mat9X& v,
                                   bool curvature, Mat9X& out) const {
  hessian_product_into(A, v, out);
  for (int u = disc_.num_soft; u < disc_.num_unknowns; ++u) {
    const Mat3 R = unflatten(F.col(u));
    Mat3 M = unflatten(out.col(u));
    if (curvature) {
      const Mat3 RtG = R.transpose() * unflatten(g.col(u));
      M -= unflatten(v.col(u)) * (0.5 * (RtG + RtG.transpose()));
    }
    const Mat3 K = R.transpose() * M;
    out.col(u) = flatten(Mat3(R * (0.5 * (K - K.transpose()))));
  }
}

double EmuSolver::energy_along(const Context& c, const Mat9X& F, const Mat9X& Fx, const Mat9X* D,
                               const Mat9X* Fd, double s) const {
  const Eigen::Index m = model_.tets.rows();
  const auto& V = disc_.geometry.volume;
  const auto& wv = acap_->weight_volume();
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    const int u = disc_.owner(t);
    Vec9 f = F.col(u), fx = Fx.col(t);
    if (D) {
      f += s * D->col(u);
      fx += s * Fd->col(t);
    }
    // Bones are rigid: no elastic energy on rotations.
    double e = 0.0;
    if (!disc_.is_bone_tet(t)) {
      const TetMaterial mat{model_.mu(t), model_.lambda(t), c.act(t), model_.fiber.row(t).transpose()};
      e = V(t) * material_energy(mat, unflatten(f));
    }
    tet_energy_[t] = e + 0.5 * emu_.alpha * wv(t) * (fx - f).squaredNorm();
  }
  double E = 0;
  for (Eigen::Index t = 0; t < m; ++t) E += tet_energy_[t];
  // Passive joint springs: k/2 (3 - tr F_b).
  for (int b = 0; b < model_.bone_stiffness.size(); ++b) {
    const int u = disc_.num_soft + b;
    const Mat3 Fb = unflatten(D ? Vec9(F.col(u) + s * D->col(u)) : Vec9(F.col(u)));
    E += 0.5 * model_.bone_stiffness(b) * (3.0 - Fb.trace());
  }
  return E;
}

void EmuSolver::gradient_into(const Context& c, const Mat9X& F, const Mat9X& Fx, Mat9X& g) const {
  const Eigen::Index m = model_.tets.rows();
  const auto& V = disc_.geometry.volume;
  const auto& wv = acap_->weight_volume();
  Mat9X per_tet(9, m);
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    const auto Fu = F.col(disc_.owner(t));
    Vec9 gt = emu_.alpha * wv(t) * (Fu - Fx.col(t));
    if (!disc_.is_bone_tet(t)) {
      const TetMaterial mat{model_.mu(t), model_.lambda(t), c.act(t), model_.fiber.row(t).transpose()};
      gt += V(t) * flatten(material_stress(mat, unflatten(Fu)));
    }
    if (c.has_gravity) gt -= wv(t) * c.F_gravity.col(t);
    per_tet.col(t) = gt;
  }
  reduce_to_unknowns(disc_, per_tet, g);
  for (int b = 0; b < model_.bone_stiffness.size(); ++b)
    g.col(disc_.num_soft + b) -= 0.5 * model_.bone_stiffness(b) * flatten(Mat3::Identity());
}

void EmuSolver::blocks_into(const Context& c, const Mat9X& F, std::vector<Mat9>* A,
                            std::vector<Mat9>* A_exact) const {
  // A_t = V_t d2Psi/dF2 + alpha w_t V_t I: PSD-filtered (A) and/or unfiltered
  // (A_exact); a bone's block is alpha sum_t w_t V_t I (rigid: no material).
  const EigenFilter filter = options_.eigen_filter == 1 ? EigenFilter::Abs : EigenFilter::Clamp;
  const int nu = disc_.num_unknowns, ns = disc_.num_soft;
  const auto& V = disc_.geometry.volume;
  const auto& wv = acap_->weight_volume();
  if (A) A->resize(nu);
  if (A_exact) A_exact->resize(nu);
  for (int u = ns; u < nu; ++u) {
    double w = 0;
    for (int i = disc_.unknown_ptr[u]; i < disc_.unknown_ptr[u + 1]; ++i) w += wv(disc_.unknown_tets[i]);
    const Mat9 Ab = emu_.alpha * w * Mat9::Identity();
    if (A) (*A)[u] = Ab;
    if (A_exact) (*A_exact)[u] = Ab;
  }
#pragma omp parallel for schedule(static)
  for (int u = 0; u < ns; ++u) {
    const int t = disc_.unknown_tets[u];
    const Mat3 Ft = unflatten(F.col(u));
    const Mat9 H = snh::hessian(Ft, model_.mu(t), model_.lambda(t));
    Mat9 fib = Mat9::Zero();
    if (c.act(t) != 0.0) fib = fiber::hessian(model_.fiber.row(t).transpose(), c.act(t));
    if (A) {
      (*A)[u] = V(t) * (psd_project<9>(H, filter) + fib);
      (*A)[u].diagonal().array() += emu_.alpha * wv(t);
    }
    if (A_exact) {
      (*A_exact)[u] = V(t) * (H + fib);
      (*A_exact)[u].diagonal().array() += emu_.alpha * wv(t);
    }
  }
}

void EmuSolver::hessian_product_into(const std::vector<Mat9>& A, const Mat9X& v, Mat9X& out) const {
  // H v = A v - alpha C^T K_c^-1 C v, and C^T K_c^-1 C v = w V F_t(x*(v)) with x*(v)
  // the homogeneous fit: one back-substitution.
  Eigen::MatrixX3d dx;
  Mat9X Fd;
  fit_linear_into(v, dx, Fd);
  const auto& wv = acap_->weight_volume();
  const Eigen::Index m = model_.tets.rows();
  if (disc_.num_bones == 0) {  // one unknown per tet: one fused pass
    out.resize(9, m);
#pragma omp parallel for schedule(static)
    for (Eigen::Index t = 0; t < m; ++t) out.col(t) = A[t] * v.col(t) - (emu_.alpha * wv(t)) * Fd.col(t);
    return;
  }
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) Fd.col(t) *= emu_.alpha * wv(t);
  reduce_to_unknowns(disc_, Fd, out);
  const long nu = disc_.num_unknowns;
#pragma omp parallel for schedule(static)
  for (long u = 0; u < nu; ++u) out.col(u) = A[u] * v.col(u) - out.col(u);
}

Mat9X EmuSolver::to_cols(const Eigen::MatrixXd& rows) const {
  if (rows.rows() != disc_.num_unknowns || rows.cols() != 9)
    throw std::invalid_argument("expected a #unknowns by 9 array (one vec(F) per soft tet, then per bone; " +
                                std::to_string(disc_.num_unknowns) + " rows), got " +
                                std::to_string(rows.rows()) + " by " + std::to_string(rows.cols()));
  if (!rows.allFinite()) throw std::invalid_argument("deformation gradients contain NaN or infinite values");
  return rows.transpose();
}

double EmuSolver::energy(const LoadCase& load, const Eigen::MatrixXd& Frows) const {
  const Context c = make_context(load);
  const Mat9X F = to_cols(Frows);
  Eigen::MatrixX3d x;
  Mat9X Fx;
  fit_into(c, F, x, Fx);
  double E = energy_along(c, F, Fx, nullptr, nullptr, 0.0);
  if (c.has_gravity) E -= (disc_.lumped_mass.transpose() * x).dot(c.gravity.transpose());
  return E;
}

Eigen::MatrixXd EmuSolver::gradient(const LoadCase& load, const Eigen::MatrixXd& Frows) const {
  const Context c = make_context(load);
  const Mat9X F = to_cols(Frows);
  Eigen::MatrixX3d x;
  Mat9X Fx, g;
  fit_into(c, F, x, Fx);
  gradient_into(c, F, Fx, g);
  return g.transpose();
}

Eigen::MatrixX3d EmuSolver::fit_positions(const LoadCase& load, const Eigen::MatrixXd& Frows) const {
  const Context c = make_context(load);
  Eigen::MatrixX3d x;
  Mat9X Fx;
  fit_into(c, to_cols(Frows), x, Fx);
  return x;
}

Eigen::MatrixXd EmuSolver::hessian_product(const LoadCase& load, const Eigen::MatrixXd& Frows,
                                           const Eigen::MatrixXd& Vrows, bool exact) const {
  const Context c = make_context(load);
  std::vector<Mat9> A, A_exact;
  blocks_into(c, to_cols(Frows), &A, &A_exact);
  Mat9X out;
  hessian_product_into(exact ? A_exact : A, to_cols(Vrows), out);
  return out.transpose();
}

Eigen::MatrixXd EmuSolver::woodbury_solve(const LoadCase& load, const Eigen::MatrixXd& Frows,
                                          const Eigen::MatrixXd& Rrows) const {
  const Context c = make_context(load);
  std::vector<Mat9> A;
  blocks_into(c, to_cols(Frows), &A, nullptr);
  Woodbury w = *woodbury_;
  if (!w.update(A)) throw std::runtime_error("Woodbury system X is not positive definite");
  Mat9X out;
  w.apply(to_cols(Rrows), out);
  return out.transpose();
}

Eigen::MatrixXd EmuSolver::block_hessians(const LoadCase& load, const Eigen::MatrixXd& Frows, bool exact) const {
  const Context c = make_context(load);
  std::vector<Mat9> A_filtered, A_exact;
  blocks_into(c, to_cols(Frows), &A_filtered, &A_exact);
  const std::vector<Mat9>& A = exact ? A_exact : A_filtered;
  Eigen::MatrixXd out(A.size(), 81);
  for (size_t t = 0; t < A.size(); ++t) out.row(t) = Eigen::Map<const Eigen::Matrix<double, 1, 81>>(A[t].data());
  return out;
}

SolveResult EmuSolver::solve(const LoadCase& load, const Eigen::MatrixXd* F0) {
  const auto t0 = Clock::now();
  const Context c = make_context(load);
  const Eigen::Index m = model_.tets.rows();
  const int nu = disc_.num_unknowns;
  Mat9X F(9, nu);
  if (F0) {
    if (F0->rows() != m || F0->cols() != 9)
      throw std::invalid_argument("the start F must be #T by 9 (one vec(F) per tet), got " +
                                  std::to_string(F0->rows()) + " by " + std::to_string(F0->cols()));
    if (!F0->allFinite()) throw std::invalid_argument("the start F contains NaN or infinite values");
    for (int u = 0; u < nu; ++u) F.col(u) = F0->row(disc_.unknown_tets[disc_.unknown_ptr[u]]).transpose();
    for (int u = disc_.num_soft; u < nu; ++u) F.col(u) = flatten(nearest_rotation(unflatten(F.col(u))));
  } else {
    for (int u = 0; u < nu; ++u) F.col(u) = flatten(Mat3::Identity());
  }
  const bool bones = disc_.num_bones > 0;
  const auto& M = disc_.lumped_mass;
  auto work = [&](const Eigen::MatrixX3d& x) {
    return c.has_gravity ? (M.transpose() * x).dot(c.gravity.transpose()) : 0.0;
  };
  Eigen::MatrixX3d x, dx;
  Mat9X Fx, Fd, g, gR, d, r, z, p, Hp, Ftrial, Fxtrial;
  Eigen::MatrixX3d xtrial;
  fit_into(c, F, x, Fx);
  double E = energy_along(c, F, Fx, nullptr, nullptr, 0.0) - work(x);
  // g: Euclidean gradient; gR: bone columns projected to the tangent space.
  auto update_gradient = [&] {
    gradient_into(c, F, Fx, g);
    gR = g;
    if (bones) project_tangent(F, gR);
  };
  update_gradient();
  double gn = gR.norm();
  double scale = 0;
  for (Eigen::Index t = 0; t < m; ++t)
    scale += disc_.geometry.volume(t) * (emu_.alpha * model_.acap_weight(t) +
                                         (disc_.is_bone_tet(t) ? 0.0 : model_.mu(t) + model_.lambda(t) + c.act(t)));
  Convergence conv{options_.rtol_grad, options_.rtol_energy, E, gn, 1e-13 * scale};
  SolveResult res;
  res.grad_norm0 = gn;
  res.history.push_back({0, E, gn, 0.0, seconds_since(t0), 0, 0});
  res.status = "max iterations reached";
  if (conv.initial()) {
    res.converged = true;
    res.status = "converged: initial state is in equilibrium";
  }
  std::vector<Mat9> A, A_exact;
  const bool exact_allowed = options_.exact_when_definite && emu_.step == EmuStep::NewtonKrylov;
  // CG on an indefinite exact Hessian need not meet negative curvature: its
  // step can be long and mostly cut by the line search. After such a step
  // (step < 1/2) the filtered Hessian is used until a full step is taken again,
  // as FEM does after a failed Cholesky.
  bool exact_ok = true;
  // With exact Hessian products the Woodbury preconditioner may lag: it is
  // rebuilt (eigen-filtered blocks, SYRK) every preconditioner_refresh
  // iterations, or sooner when CG slows down by half since the last rebuild.
  int since_refresh = 0, cg_after_refresh = -1, last_cg = 0;
  // Bones: the Woodbury term sees a bone's block as stiff as its ACAP weight
  // (alpha sum w V), while turning a bone with the soft tissue following is
  // cheap; CG then spends many iterations on the bones' rotations. A coarse
  // correction over Z = {turn bone b about axis k, soft F_t following the
  // fitted positions} (3 per bone) adds Z (Z^T H Z)^-1 Z^T (additive
  // two-level preconditioner; rebuilt with the Woodbury term).
  std::vector<Mat9X> coarse_Z, coarse_HZ;
  Eigen::MatrixXd coarse_inv;  // pseudo-inverse of Z^T H Z
  bool coarse_ok = false, balancing = false;
  std::vector<std::pair<int, Vec3>> neutral;  // bone turns of zero curvature (neutral modes)
  auto build_coarse = [&](const std::vector<Mat9>& Ablocks, bool curvature) {
    const int nz = 3 * disc_.num_bones;
    coarse_Z.assign(nz, Mat9X::Zero(9, nu));
    coarse_HZ.resize(nz);
    Eigen::MatrixX3d dxk;
    Mat9X Fdk, HZ;
    for (int b = 0; b < disc_.num_bones; ++b)
      for (int k = 0; k < 3; ++k) {
        Mat9X& Z = coarse_Z[3 * b + k];
        const int ub = disc_.num_soft + b;
        Mat3 W = Mat3::Zero();
        W((k + 2) % 3, (k + 1) % 3) = 1.0;
        W((k + 1) % 3, (k + 2) % 3) = -1.0;
        Z.col(ub) = flatten(Mat3(W * unflatten(F.col(ub))));
        fit_linear_into(Z, dxk, Fdk);
        for (int u = 0; u < disc_.num_soft; ++u) Z.col(u) = Fdk.col(disc_.unknown_tets[u]);
      }
    Eigen::MatrixXd E(nz, nz);
    for (int j = 0; j < nz; ++j) {
      riemannian_product(Ablocks, F, g, coarse_Z[j], curvature, coarse_HZ[j]);
      for (int i = 0; i < nz; ++i) E(i, j) = dot(coarse_Z[i], coarse_HZ[j]);
    }
    // A turn of zero curvature (nothing resists it: a neutral mode) is left
    // out of the correction and reported. Scale: the curvature of turning the
    // bone's volume against an ACAP term of weight 1, 2 alpha sum_t V_t (not the
    // bone's own, much larger, weight: a soft but real resistance, such as a
    // muscle's torsion, must not count as none).
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (E + E.transpose()));
    double scale = std::numeric_limits<double>::infinity();
    for (int u = disc_.num_soft; u < nu; ++u) {
      double vol = 0;
      for (int i = disc_.unknown_ptr[u]; i < disc_.unknown_ptr[u + 1]; ++i)
        vol += disc_.geometry.volume(disc_.unknown_tets[i]);
      scale = std::min(scale, 2.0 * emu_.alpha * vol);
    }
    coarse_inv.setZero(nz, nz);
    neutral.clear();
    balancing = true;
    for (int i = 0; i < nz; ++i) {
      const Eigen::VectorXd v = es.eigenvectors().col(i);
      if (es.eigenvalues()(i) > 1e-9 * scale) {
        coarse_inv += v * v.transpose() / es.eigenvalues()(i);
        continue;
      }
      balancing = false;
      if (es.eigenvalues()(i) < -1e-9 * scale) continue;  // negative curvature: not a neutral mode
      int best = 0;
      for (int b = 1; b < disc_.num_bones; ++b)
        if (v.segment<3>(3 * b).norm() > v.segment<3>(3 * best).norm()) best = b;
      neutral.push_back({best, v.segment<3>(3 * best).normalized()});
    }
    coarse_ok = true;
  };
  Mat9X r1;
  auto precondition = [&](const Mat9X& in, Mat9X& out) {
    const size_t nz = coarse_Z.size();
    if (bones && coarse_ok && balancing) {
      // Balancing: M^-1 r = Q r + (I - Q H) B (I - H Q) r, Q = Z E^-1 Z^T.
      Eigen::VectorXd zr(nz);
      for (size_t i = 0; i < nz; ++i) zr(i) = dot(coarse_Z[i], in);
      const Eigen::VectorXd c1 = coarse_inv * zr;
      r1 = in;
      for (size_t i = 0; i < nz; ++i) r1 -= c1(i) * coarse_HZ[i];
      woodbury_->apply(r1, out);
      project_tangent(F, out);
      for (size_t i = 0; i < nz; ++i) zr(i) = dot(coarse_HZ[i], out);
      const Eigen::VectorXd c2 = coarse_inv * zr;
      for (size_t i = 0; i < nz; ++i) out += (c1(i) - c2(i)) * coarse_Z[i];
      return;
    }
    if (schur_) schur_->apply(in, out);
    else woodbury_->apply(in, out);
    if (!bones) return;
    project_tangent(F, out);
    if (!coarse_ok) return;
    Eigen::VectorXd zr(nz);
    for (size_t i = 0; i < nz; ++i) zr(i) = dot(coarse_Z[i], in);
    const Eigen::VectorXd c = coarse_inv * zr;
    for (size_t i = 0; i < nz; ++i) out += c(i) * coarse_Z[i];
  };
  for (int it = 1; !res.converged && it <= options_.max_iterations; ++it) {
    if (options_.interrupted && options_.interrupted()) {
      res.status = "interrupted";
      break;
    }
    const bool exact = exact_allowed && exact_ok;
    if (exact_allowed && !exact) ++res.filtered_steps;
    const bool refresh = !exact || it == 1 || since_refresh >= emu_.preconditioner_refresh ||
                         (cg_after_refresh >= 0 && last_cg > 1.5 * cg_after_refresh + 5);
    if (refresh) {
      blocks_into(c, F, &A, exact ? &A_exact : nullptr);
      if (schur_) {
        if (!schur_->update(A)) {
          res.status = "Schur-complement preconditioner could not be factorised";
          break;
        }
      } else {
        woodbury_->update(A);
      }
      since_refresh = 0;
      cg_after_refresh = -1;
    } else {
      blocks_into(c, F, nullptr, &A_exact);
    }
    // The coarse space follows the Hessian CG uses (rebuilt every step: 3 fits
    // and 3 products per bone).
    if (bones && emu_.bone_coarse_space) build_coarse(exact ? A_exact : A, exact);
    ++since_refresh;
    int cg_its = 0;
    if (emu_.step == EmuStep::Woodbury) {
      precondition(gR, d);
      d = -d;
    } else {
      // Inexact Newton: PCG on H d = -g to |r| <= eta |g| (Eisenstat-Walker).
      const double eta = std::min(emu_.cg_forcing_max, std::pow(gn / conv.g0, emu_.cg_forcing_exponent));
      d.setZero(9, nu);
      r = -gR;
      precondition(r, z);
      p = z;
      double rz = dot(r, z);
      for (int i = 0; i < emu_.cg_max_iterations; ++i) {
        if (bones) riemannian_product(exact ? A_exact : A, F, g, p, exact, Hp);
        else hessian_product_into(exact ? A_exact : A, p, Hp);
        const double pHp = dot(p, Hp);
        if (!(pHp > 0)) {  // negative curvature (exact H is indefinite here): keep what we have
          if (i == 0) d = z;
          ++res.filtered_steps;
          break;
        }
        const double a = rz / pHp;
        d += a * p;
        r -= a * Hp;
        ++cg_its;
        if (r.norm() <= eta * gn) break;
        precondition(r, z);
        const double rz_new = dot(r, z);
        p = z + (rz_new / rz) * p;
        rz = rz_new;
      }
    }
    double slope = dot(gR, d);
    if (!(slope < 0)) {
      precondition(gR, d);
      d = -d;
      slope = dot(gR, d);
      if (!(slope < 0)) {
        res.status = "no descent direction (Hessian approximation broke down)";
        break;
      }
    }
    // Without bones x*(F + s d) = x + s dx (one fit per direction); a bone's
    // path R + s d is retracted to rotations, so each trial refits.
    const double Wx = work(x);
    double Wdx = 0;
    if (!bones) {
      fit_linear_into(d, dx, Fd);
      Wdx = work(dx);
    }
    auto energy_at = [&](double s) {
      if (!bones) return energy_along(c, F, Fx, &d, &Fd, s) - Wx - s * Wdx;
      retract(F, d, s, Ftrial);
      fit_into(c, Ftrial, xtrial, Fxtrial);
      return energy_along(c, Ftrial, Fxtrial, nullptr, nullptr, 0.0) - work(xtrial);
    };
    auto ls = armijo_backtracking(energy_at, E, slope, options_);
    if (!ls.success) {
      const double E1 = energy_at(1.0);
      Mat9X g1;
      if (bones) {
        gradient_into(c, Ftrial, Fxtrial, g1);
        project_tangent(Ftrial, g1);
      } else {
        Mat9X F1 = F + d, Fx1 = Fx + Fd;
        gradient_into(c, F1, Fx1, g1);
      }
      if (accept_at_roundoff(E1, g1.norm(), E, gn, conv.E0)) {
        ls.success = true;
        ls.step = 1.0;
        ls.energy = E1;
      } else {
        res.status = "stalled: no step along the search direction decreases the energy or the gradient "
                     "(round-off level reached; loosen rtol_grad / rtol_energy)";
        break;
      }
    }
    const double E_prev = E;
    if (bones) {
      retract(F, d, ls.step, Ftrial);
      F = Ftrial;
      fit_into(c, F, x, Fx);
      E = ls.energy;
    } else {
      F += ls.step * d;
      if (it % 50 == 0) {
        fit_into(c, F, x, Fx);  // x*(F) is linear in F; refit now and then against drift
      } else {
        x += ls.step * dx;
        Fx += ls.step * Fd;
      }
      E = (it % 50 == 0) ? energy_along(c, F, Fx, nullptr, nullptr, 0.0) - work(x) : ls.energy;
    }
    update_gradient();
    gn = gR.norm();
    res.iterations = it;
    res.cg_iterations += cg_its;
    last_cg = cg_its;
    if (cg_after_refresh < 0) cg_after_refresh = cg_its;
    res.history.push_back({it, E, gn, ls.step, seconds_since(t0), cg_its, ls.backtracks});
    if (exact_allowed) exact_ok = exact ? ls.step >= 0.5 : ls.step == 1.0;
    if (conv.test(E_prev, E, gn)) {
      res.converged = true;
      res.status = "converged";
    }
  }
  res.neutral_axes.resize(neutral.size(), 3);
  for (size_t i = 0; i < neutral.size(); ++i) {
    res.neutral_bones.push_back(neutral[i].first);
    res.neutral_axes.row(i) = neutral[i].second.transpose();
  }
  fit_into(c, F, x, Fx);
  res.positions = x;
  Mat9X Ft;
  expand_unknowns(disc_, F, Ft);
  res.F = Ft.transpose();
  res.energy = E;
  res.grad_norm = gn;
  res.rel_energy_change = conv.rel_energy_change;
  res.time_s = seconds_since(t0);
  return res;
}

}  // namespace emu
