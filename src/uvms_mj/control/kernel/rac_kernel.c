// The per-sample algebra of the generic RAC (uvms_mj/control/rac.py) in one compiled routine.
//
// The same steps, in the same order, as RAC.compute in rac.py (the reference implementation and
// the fallback without a C compiler; tests/test_rac_kernel.py checks that both give the same
// commands and signals to round-off). The equation numbers are the paper's (see rac.py and
// docs/paper-reading.md). Three calls per sample, with Python in between for what stays there:
//
//   uvms_rac_measure   nominal model at the measured state (Eqs. 6-7: mj_forward's position and
//                      velocity stages, mj_fullM,
//                      qfrc_bias - qfrc_passive), Jacobians (mj_jacBody, mj_jacSite), the task
//                      p and J, the measured task velocity, the arm's manipulability;
//   (Python)           Eq. 12 (SingularHandler: the base's desired velocity) and the desired tip
//                      at k + 1;
//   uvms_rac_command   the desired point p_d(k+1) (base reference + Eq. 12 offset, tip; p_d(k) is
//                      the last sample's), Eqs. 10-11, Eq. 9 (block solution), the arm's joint-limit
//                      clamp (ours: limits.clamp_joint_acceleration), Eqs. 13 and 15, the base force as a
//                      body wrench, the "clip" allocation or the "wls" Allocator's fast path
//                      (returns 1 when that does not apply: Python's Allocator gives the thrusts);
//   uvms_rac_finish    the achieved base force, the observers' updates (Eq. 14 corrected,
//                      Fig. 3(b)), the joint torques and the state for the next sample.
//
// Every array is owned by Python (numpy); the struct holds their addresses. Matrices are dense
// row-major. Return values: 0 ok, 1 (command) allocate in Python, -1 singular matrix.

#include <math.h>
#include <string.h>

#include <mujoco/mujoco.h>

#define MAXN 32  // largest task, arm or dof count handled (checked in Python: rac_kernel.MAXN)

typedef struct {
  // sizes and flags (fixed at reset)
  int nq, nv, nb, na, ntask, nbt, ntr, nvec;
  int free_base, tip_orient, square, observer, observer_arm, clip_alloc, alloc_input;
  int nthr, nwr, nmot, base_body, tip_site, base_qadr, wls_fast;
  int nbv, nlin;  // base entries of a desired point (p_d = base, tip), of them the Eq. 12 offset's
  int joint_limits;  // clamp the arm's desired accelerations (uvms_mj/control/limits.py's velocity damper)
  // index arrays
  const int *base_dofs, *arm_dofs, *tip_rows, *base_qpos, *arm_qadr, *wrench_rows, *motor_idx;
  const int* lin;  // where the offset's entries are in the base part of p_d
  // parameters
  double T, dls_threshold, dls_damping, null_kp, null_kd, g, h, g_arm, h_arm;
  double jl_beta;  // the damper's beta = T / tau
  const double *gamma, *lam, *q_rest, *Jb, *Jb_pinvT, *B, *B_pinv, *lo, *hi, *motor_lo, *motor_hi, *Q;
  const double *jnt_lo, *jnt_hi;  // the arm joints' bounds (nominal range minus the margin; +-inf: none)
  // per-sample inputs (q, measured qd) and desired points p_d(k), p_d(k+1): vector, rotations
  double *q, *qd_meas, *pd, *Rd, *pdn, *Rdn;
  // state carried to the next sample
  double *q_prev, *p_prev, *R_prev, *J_prev, *e_p_prev, *pd_prev, *Rd_prev, *z, *z_arm;
  // per-sample results
  double *qd, *M, *hb, *J, *p, *R, *R_base, *pd_meas, *scalars;  // scalars: manip, det_B, dls, mu2
  double *e_p, *e_v, *v_d, *a_d, *qdd, *u_B, *u_app, *f_e_hat, *f_m_hat, *f_t, *f_tM, *u_M;
  double *body, *thrust, *sat, *torques, *base_quat;
  // desired points (Python gives the tip at k + 1 and Eq. 12's base velocity when it moves the
  // offset): base reference, the Eq. 12 offset (state), its velocity, the tip; p_d(k) as output
  double *ref, *off, *v_base, *tipn, *pd_out;
  // the controller's nominal model and its data
  const mjModel* m;
  mjData* d;
} uvms_rac;

// ------------------------------------------------------------------ small dense algebra

// Determinant, closed form for n <= 3 (as rac.small_det), else LU with partial pivoting.
static double det_small(const double* A, int n) {
  if (n == 1) return A[0];
  if (n == 2) return A[0] * A[3] - A[1] * A[2];
  if (n == 3) {
    double a = A[0], b = A[1], c = A[2], d = A[3], e = A[4], f = A[5], g = A[6], h = A[7], i = A[8];
    return a * (e * i - f * h) + b * (f * g - d * i) + c * (d * h - e * g);
  }
  double W[MAXN * MAXN];
  memcpy(W, A, sizeof(double) * n * n);
  double det = 1.0;
  for (int k = 0; k < n; k++) {
    int p = k;
    for (int r = k + 1; r < n; r++) if (fabs(W[r * n + k]) > fabs(W[p * n + k])) p = r;
    if (W[p * n + k] == 0.0) return 0.0;
    if (p != k) {
      for (int c = 0; c < n; c++) { double t = W[k * n + c]; W[k * n + c] = W[p * n + c]; W[p * n + c] = t; }
      det = -det;
    }
    det *= W[k * n + k];
    for (int r = k + 1; r < n; r++) {
      double f = W[r * n + k] / W[k * n + k];
      for (int c = k; c < n; c++) W[r * n + c] -= f * W[k * n + c];
    }
  }
  return det;
}

// Inverse: closed form (adjugate / determinant) for n <= 3 as rac.small_inv, else Gauss-Jordan
// with partial pivoting. Returns -1 for a singular matrix.
static int inv_small(double* out, const double* A, int n) {
  if (n == 1) {
    if (A[0] == 0.0) return -1;
    out[0] = 1.0 / A[0];
    return 0;
  }
  if (n == 2) {
    double a = A[0], b = A[1], c = A[2], d = A[3], det = a * d - b * c;
    if (det == 0.0) return -1;
    out[0] = d / det; out[1] = -b / det; out[2] = -c / det; out[3] = a / det;
    return 0;
  }
  if (n == 3) {
    double a = A[0], b = A[1], c = A[2], d = A[3], e = A[4], f = A[5], g = A[6], h = A[7], i = A[8];
    double co0 = e * i - f * h, co1 = f * g - d * i, co2 = d * h - e * g;
    double det = a * co0 + b * co1 + c * co2;
    if (det == 0.0) return -1;
    double adj[9] = {co0, c * h - b * i, b * f - c * e, co1, a * i - c * g, c * d - a * f,
                     co2, b * g - a * h, a * e - b * d};
    for (int k = 0; k < 9; k++) out[k] = adj[k] / det;
    return 0;
  }
  double W[MAXN * MAXN];
  memcpy(W, A, sizeof(double) * n * n);
  for (int r = 0; r < n; r++) for (int c = 0; c < n; c++) out[r * n + c] = (r == c);
  for (int k = 0; k < n; k++) {
    int p = k;
    for (int r = k + 1; r < n; r++) if (fabs(W[r * n + k]) > fabs(W[p * n + k])) p = r;
    if (W[p * n + k] == 0.0) return -1;
    if (p != k) {
      for (int c = 0; c < n; c++) {
        double t = W[k * n + c]; W[k * n + c] = W[p * n + c]; W[p * n + c] = t;
        t = out[k * n + c]; out[k * n + c] = out[p * n + c]; out[p * n + c] = t;
      }
    }
    double piv = W[k * n + k];
    for (int c = 0; c < n; c++) { W[k * n + c] /= piv; out[k * n + c] /= piv; }
    for (int r = 0; r < n; r++) {
      if (r == k) continue;
      double f = W[r * n + k];
      if (f == 0.0) continue;
      for (int c = 0; c < n; c++) { W[r * n + c] -= f * W[k * n + c]; out[r * n + c] -= f * out[k * n + c]; }
    }
  }
  return 0;
}

// ------------------------------------------------------------------ rotations (rotations.py)

static void quat_to_mat(double* R, const double* q4) {
  double n = sqrt(q4[0] * q4[0] + q4[1] * q4[1] + q4[2] * q4[2] + q4[3] * q4[3]);
  double w = q4[0] / n, x = q4[1] / n, y = q4[2] / n, z = q4[3] / n;
  R[0] = 1 - 2 * (y * y + z * z); R[1] = 2 * (x * y - w * z);     R[2] = 2 * (x * z + w * y);
  R[3] = 2 * (x * y + w * z);     R[4] = 1 - 2 * (x * x + z * z); R[5] = 2 * (y * z - w * x);
  R[6] = 2 * (x * z - w * y);     R[7] = 2 * (y * z + w * x);     R[8] = 1 - 2 * (x * x + y * y);
}

// Rotation vector of R (rotations.rotation_log).
static void rotation_log(double* out, const double* R) {
  double c = 0.5 * (R[0] + R[4] + R[8] - 1.0);
  c = c > 1.0 ? 1.0 : (c < -1.0 ? -1.0 : c);
  double a = acos(c);
  double wx = R[7] - R[5], wy = R[2] - R[6], wz = R[3] - R[1];
  if (a < 1e-6) { out[0] = 0.5 * wx; out[1] = 0.5 * wy; out[2] = 0.5 * wz; return; }
  if (M_PI - a < 1e-6) {  // near pi: axis from the symmetric part
    double Bs[9], ax[3];
    for (int k = 0; k < 9; k++) Bs[k] = 0.5 * (R[k] + (k % 4 == 0 ? 1.0 : 0.0));
    for (int k = 0; k < 3; k++) ax[k] = sqrt(Bs[4 * k] > 0.0 ? Bs[4 * k] : 0.0);
    int i = 0;
    for (int k = 1; k < 3; k++) if (ax[k] > ax[i]) i = k;
    double d = ax[i] > 1e-12 ? ax[i] : 1e-12;
    double v[3] = {Bs[3 * i] / d, Bs[3 * i + 1] / d, Bs[3 * i + 2] / d};
    double nv = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int k = 0; k < 3; k++) out[k] = a * v[k] / nv;
    return;
  }
  double k = a / (2.0 * sin(a));
  out[0] = k * wx; out[1] = k * wy; out[2] = k * wz;
}

// log(Ra Rb^T); exactly 0 for the same matrix (rac.py: the same desired attitude object).
static void rot_diff(double* out, const double* Ra, const double* Rb) {
  if (memcmp(Ra, Rb, 9 * sizeof(double)) == 0) { out[0] = out[1] = out[2] = 0.0; return; }
  double P[9];
  for (int r = 0; r < 3; r++)
    for (int c = 0; c < 3; c++)
      P[3 * r + c] = Ra[3 * r] * Rb[3 * c] + Ra[3 * r + 1] * Rb[3 * c + 1] + Ra[3 * r + 2] * Rb[3 * c + 2];
  rotation_log(out, P);
}

// a - b in the task space (RAC._diff): vectors (base position, tip position) and rotations.
static void task_diff(const uvms_rac* s, double* out, const double* va, const double* Ra,
                      const double* vb, const double* Rb) {
  if (!s->free_base) {
    for (int i = 0; i < s->ntask; i++) out[i] = va[i] - vb[i];
    return;
  }
  for (int i = 0; i < 3; i++) out[i] = va[i] - vb[i];
  rot_diff(out + 3, Ra, Rb);
  for (int i = 0; i < 3; i++) out[6 + i] = va[3 + i] - vb[3 + i];
  if (s->tip_orient) rot_diff(out + 9, Ra + 9, Rb + 9);
}

// ------------------------------------------------------------------ the three stages

// Nominal model at the measured state, task, Jacobian, manipulability. first: k <= k0.
int uvms_rac_measure(uvms_rac* s, int first, int has_qd) {
  const mjModel* m = s->m;
  mjData* d = s->d;
  int nv = s->nv, nq = s->nq, nt = s->ntask, nbt = s->nbt, ntr = s->ntr, na = s->na;
  if (has_qd) mju_copy(s->qd, s->qd_meas, nv);
  else if (first) mju_zero(s->qd, nv);
  else mj_differentiatePos(m, s->qd, s->T, s->q_prev, s->q);  // backward difference as qvel
  // Eqs. 6-7 on the nominal model: M and h = qfrc_bias - qfrc_passive
  mju_copy(d->qpos, s->q, nq);
  mju_copy(d->qvel, s->qd, nv);
  d->time = 0.0;
  mj_fwdPosition(m, d);  // mj_forward's position and velocity stages: all that M, h and the
  mj_fwdVelocity(m, d);  // Jacobians need (the passive stage runs the hydrodynamics plugins)
  mj_fullM(m, d, s->M);
  for (int i = 0; i < nv; i++) s->hb[i] = d->qfrc_bias[i] - d->qfrc_passive[i];
  // Jacobians (world rows) of the vehicle origin and the tip
  double jbp[3 * MAXN], jbr[3 * MAXN], jtp[3 * MAXN], jtr[3 * MAXN];
  mj_jacBody(m, d, jbp, jbr, s->base_body);
  mj_jacSite(m, d, jtp, jtr, s->tip_site);
  mju_copy(s->R_base, d->xmat + 9 * s->base_body, 9);
  const double* tip = d->site_xpos + 3 * s->tip_site;
  double* J = s->J;
  if (s->free_base) {
    mju_copy(J, jbp, 3 * nv);
    mju_copy(J + 3 * nv, jbr, 3 * nv);
    mju_copy(J + 6 * nv, jtp, 3 * nv);
    if (s->tip_orient) mju_copy(J + 9 * nv, jtr, 3 * nv);
    int a = s->base_qadr;
    for (int i = 0; i < 3; i++) { s->p[i] = s->q[a + i]; s->p[3 + i] = tip[i]; }
    quat_to_mat(s->R, s->q + a + 3);
    if (s->tip_orient) mju_copy(s->R + 9, d->site_xmat + 9 * s->tip_site, 9);
  } else {  // base rows: the identity on the base dofs; tip rows: the tip's along the slides
    mju_zero(J, nt * nv);
    for (int i = 0; i < s->nb; i++) J[i * nv + s->base_dofs[i]] = 1.0;
    for (int i = 0; i < ntr; i++) mju_copy(J + (nbt + i) * nv, jtp + s->tip_rows[i] * nv, nv);
    for (int i = 0; i < s->nb; i++) s->p[i] = s->q[s->base_qpos[i]];
    for (int i = 0; i < ntr; i++) s->p[s->nb + i] = tip[s->tip_rows[i]];
  }
  // measured task velocity
  if (has_qd) {
    for (int i = 0; i < nt; i++) {
      double acc = 0.0;
      for (int j = 0; j < nv; j++) acc += J[i * nv + j] * s->qd[j];
      s->pd_meas[i] = acc;
    }
  } else if (first) {
    mju_zero(s->pd_meas, nt);
  } else {
    task_diff(s, s->pd_meas, s->p, s->R, s->p_prev, s->R_prev);
    for (int i = 0; i < nt; i++) s->pd_meas[i] /= s->T;
  }
  // the arm Jacobian B (tip rows, arm dofs) and its manipulability (|det B| when square)
  double Bm[MAXN * MAXN];
  for (int i = 0; i < ntr; i++)
    for (int j = 0; j < na; j++) Bm[i * na + j] = J[(nbt + i) * nv + s->arm_dofs[j]];
  double manip, detb;
  if (s->square) {
    detb = det_small(Bm, na);
    manip = fabs(detb);
  } else {
    double G[MAXN * MAXN];
    for (int i = 0; i < ntr; i++)
      for (int k = 0; k < ntr; k++) {
        double acc = 0.0;
        for (int j = 0; j < na; j++) acc += Bm[i * na + j] * Bm[k * na + j];
        G[i * ntr + k] = acc;
      }
    detb = NAN;
    double dg = det_small(G, ntr);
    manip = sqrt(dg > 0.0 ? dg : 0.0);
  }
  s->scalars[0] = manip;
  s->scalars[1] = detb;
  return 0;
}

// Eqs. 10-11, Eq. 9, Eqs. 13 and 15, allocation ("clip"). Returns 1 when Python allocates.
int uvms_rac_command(uvms_rac* s, int first, int moving) {
  int nv = s->nv, nt = s->ntask, nbt = s->nbt, ntr = s->ntr, na = s->na, nb = s->nb;
  const double T = s->T;
  // p_d(k + 1) (RAC._desired): the base reference plus the Eq. 12 offset, which moves by T v
  // when the base follows (off(k+1) = off(k) + T v_base), and the tip at k + 1
  if (moving)
    for (int j = 0; j < s->nlin; j++) s->off[j] += T * s->v_base[j];
  for (int i = 0; i < s->nbv; i++) s->pdn[i] = s->ref[i];
  for (int j = 0; j < s->nlin; j++) s->pdn[s->lin[j]] += s->off[j];
  for (int i = s->nbv; i < s->nvec; i++) s->pdn[i] = s->tipn[i - s->nbv];
  const double* J = s->J;
  const double* M = s->M;
  const int *b = s->base_dofs, *a = s->arm_dofs;
  double tmp[MAXN], tmp2[MAXN], rhs[MAXN];
  // Eq. 11 at k and k + 1, Eq. 10
  task_diff(s, s->e_p, s->pd, s->Rd, s->p, s->R);
  task_diff(s, tmp, s->pd, s->Rd, s->pd_prev, s->Rd_prev);
  task_diff(s, tmp2, s->pdn, s->Rdn, s->pd, s->Rd);
  for (int i = 0; i < nt; i++) {
    s->v_d[i] = (tmp[i] + s->gamma[i] * s->e_p_prev[i]) / T;
    double v_dn = (tmp2[i] + s->gamma[i] * s->e_p[i]) / T;
    s->e_v[i] = s->v_d[i] - s->pd_meas[i];
    s->a_d[i] = (v_dn - s->v_d[i] + s->lam[i] * s->e_v[i]) / T;
    rhs[i] = s->a_d[i];
  }
  // J q_ddot = a_d - J_dot q_dot, J_dot by backward difference (Eq. 9)
  if (!first) {
    for (int i = 0; i < nt; i++) {
      double acc = 0.0;
      for (int j = 0; j < nv; j++) acc += (J[i * nv + j] - s->J_prev[i * nv + j]) * s->qd[j];
      rhs[i] -= acc / T;
    }
  }
  double* qdd = s->qdd;
  mju_zero(qdd, nv);
  if (s->free_base) {  // S = [[I, 0], [0, R]]
    for (int i = 0; i < 3; i++) qdd[b[i]] = rhs[i];
    const double* Rb = s->R_base;
    for (int i = 0; i < 3; i++) qdd[b[3 + i]] = Rb[i] * rhs[3] + Rb[3 + i] * rhs[4] + Rb[6 + i] * rhs[5];
  } else {
    for (int i = 0; i < nbt; i++) qdd[b[i]] = rhs[i];
  }
  double r_m[MAXN], Bm[MAXN * MAXN];
  for (int i = 0; i < ntr; i++) {
    double acc = 0.0;
    for (int j = 0; j < nb; j++) acc += J[(nbt + i) * nv + b[j]] * qdd[b[j]];
    r_m[i] = rhs[nbt + i] - acc;
    for (int j = 0; j < na; j++) Bm[i * na + j] = J[(nbt + i) * nv + a[j]];
  }
  double manip = s->scalars[0];
  int dls = manip < s->dls_threshold;
  double mu2 = dls ? s->dls_damping * s->dls_damping * (1.0 - (manip / s->dls_threshold) * (manip / s->dls_threshold))
                   : 0.0;
  s->scalars[2] = dls;
  s->scalars[3] = mu2;
  double Inv[MAXN * MAXN], G[MAXN * MAXN];
  if (s->square) {
    if (dls) {  // B^T (B B^T + mu^2 I)^-1 r_m
      for (int i = 0; i < ntr; i++)
        for (int k = 0; k < ntr; k++) {
          double acc = 0.0;
          for (int j = 0; j < na; j++) acc += Bm[i * na + j] * Bm[k * na + j];
          G[i * ntr + k] = acc + (i == k ? mu2 : 0.0);
        }
      if (inv_small(Inv, G, ntr)) return -1;
      for (int i = 0; i < ntr; i++) {
        double acc = 0.0;
        for (int k = 0; k < ntr; k++) acc += Inv[i * ntr + k] * r_m[k];
        tmp[i] = acc;
      }
      for (int j = 0; j < na; j++) {
        double acc = 0.0;
        for (int i = 0; i < ntr; i++) acc += Bm[i * na + j] * tmp[i];
        qdd[a[j]] = acc;
      }
    } else {
      if (inv_small(Inv, Bm, na)) return -1;
      for (int j = 0; j < na; j++) {
        double acc = 0.0;
        for (int i = 0; i < ntr; i++) acc += Inv[j * ntr + i] * r_m[i];
        qdd[a[j]] = acc;
      }
    }
  } else {  // weighted pseudo-inverse B# = W^-1 B^T (B W^-1 B^T + mu^2 I)^-1, W = M_MM
    double Maa[MAXN * MAXN], Mi[MAXN * MAXN], X[MAXN * MAXN], Bp[MAXN * MAXN], q0dd[MAXN];
    for (int i = 0; i < na; i++)
      for (int j = 0; j < na; j++) Maa[i * na + j] = M[a[i] * nv + a[j]];
    if (inv_small(Mi, Maa, na)) return -1;
    for (int i = 0; i < na; i++)  // X = M_MM^-1 B^T (na x ntr)
      for (int k = 0; k < ntr; k++) {
        double acc = 0.0;
        for (int j = 0; j < na; j++) acc += Mi[i * na + j] * Bm[k * na + j];
        X[i * ntr + k] = acc;
      }
    for (int i = 0; i < ntr; i++)
      for (int k = 0; k < ntr; k++) {
        double acc = 0.0;
        for (int j = 0; j < na; j++) acc += Bm[i * na + j] * X[j * ntr + k];
        G[i * ntr + k] = acc + (i == k ? mu2 : 0.0);
      }
    if (inv_small(Inv, G, ntr)) return -1;
    for (int i = 0; i < na; i++)
      for (int k = 0; k < ntr; k++) {
        double acc = 0.0;
        for (int j = 0; j < ntr; j++) acc += X[i * ntr + j] * Inv[j * ntr + k];
        Bp[i * ntr + k] = acc;
      }
    for (int j = 0; j < na; j++)  // null-space posture term
      q0dd[j] = s->null_kp * (s->q_rest[j] - s->q[s->arm_qadr[j]]) - s->null_kd * s->qd[a[j]];
    for (int i = 0; i < ntr; i++) {  // r_m - B q0dd
      double acc = 0.0;
      for (int j = 0; j < na; j++) acc += Bm[i * na + j] * q0dd[j];
      tmp[i] = r_m[i] - acc;
    }
    for (int j = 0; j < na; j++) {
      double acc = 0.0;
      for (int i = 0; i < ntr; i++) acc += Bp[j * ntr + i] * tmp[i];
      qdd[a[j]] = acc + q0dd[j];
    }
  }
  // ours: each arm joint's desired acceleration inside the discrete velocity damper's bounds
  // (limits.clamp_joint_acceleration: a_hi = (beta (hi - q) / T - (1 + beta) qd) / (T (1 + beta / 2)))
  if (s->joint_limits) {
    const double beta = s->jl_beta, den = T * (1.0 + 0.5 * beta);
    for (int j = 0; j < na; j++) {
      double qj = s->q[s->arm_qadr[j]], vj = s->qd[a[j]];
      double a_hi = (beta * (s->jnt_hi[j] - qj) / T - (1.0 + beta) * vj) / den;
      double a_lo = (beta * (s->jnt_lo[j] - qj) / T - (1.0 + beta) * vj) / den;
      double v = qdd[a[j]];
      v = v > a_lo ? v : a_lo;
      qdd[a[j]] = v < a_hi ? v : a_hi;
    }
  }
  // Computed torque on the nominal model (Eq. 7 blocks), Eqs. 13 and 15
  for (int i = 0; i < na; i++) {
    double acc = 0.0, macc = 0.0, qacc = 0.0;
    for (int j = 0; j < nb; j++) acc += M[a[i] * nv + b[j]] * qdd[b[j]];
    s->f_tM[i] = acc + s->hb[a[i]];
    for (int j = 0; j < na; j++) { macc += M[a[i] * nv + a[j]] * qdd[a[j]]; qacc += M[a[i] * nv + a[j]] * s->qd[a[j]]; }
    s->f_m_hat[i] = s->observer_arm ? s->z_arm[i] - s->g_arm * qacc : 0.0;
    s->u_M[i] = macc + s->f_tM[i] + s->f_m_hat[i];
  }
  for (int i = 0; i < nb; i++) {
    double acc = 0.0, macc = 0.0, qacc = 0.0;
    for (int j = 0; j < na; j++) acc += M[b[i] * nv + a[j]] * qdd[a[j]];
    s->f_t[i] = acc + s->hb[b[i]];  // Eq. 13
    for (int j = 0; j < nb; j++) { macc += M[b[i] * nv + b[j]] * qdd[b[j]]; qacc += M[b[i] * nv + b[j]] * s->qd[b[j]]; }
    s->f_e_hat[i] = s->observer ? s->z[i] - s->g * qacc : 0.0;
    s->u_B[i] = macc + s->f_t[i] + s->f_e_hat[i];  // Eq. 15
  }
  // the base force as a body-frame wrench at the vehicle origin: u_B = Jb^T w
  const double* Rb = s->R_base;
  double* body = s->body;
  if (s->free_base) {
    for (int i = 0; i < 3; i++) {
      body[i] = Rb[i] * s->u_B[0] + Rb[3 + i] * s->u_B[1] + Rb[6 + i] * s->u_B[2];
      body[3 + i] = s->u_B[3 + i];
    }
  } else {
    double w[6];
    for (int i = 0; i < 6; i++) {
      double acc = 0.0;
      for (int j = 0; j < nb; j++) acc += s->Jb_pinvT[i * nb + j] * s->u_B[j];
      w[i] = acc;
    }
    for (int i = 0; i < 3; i++) {
      body[i] = Rb[i] * w[0] + Rb[3 + i] * w[1] + Rb[6 + i] * w[2];
      body[3 + i] = Rb[i] * w[3] + Rb[3 + i] * w[4] + Rb[6 + i] * w[5];
    }
  }
  if (!s->clip_alloc) {
    // "wls": the Allocator's fast path (every thruster free: u = P S tau, Q = P S, the answer
    // when inside the box); otherwise Python's Allocator redistributes
    if (!s->wls_fast) return 1;
    for (int i = 0; i < s->nthr; i++) {
      double acc = 0.0;
      for (int j = 0; j < s->nwr; j++) acc += s->Q[i * s->nwr + j] * body[s->wrench_rows[j]];
      if (!(acc <= s->hi[i] && acc >= s->lo[i])) return 1;
      s->thrust[i] = acc;
      s->sat[i] = 0.0;
    }
    return 0;
  }
  // least squares on the rows the base can move, then clipped to the limits
  for (int i = 0; i < s->nthr; i++) {
    double acc = 0.0;
    for (int j = 0; j < s->nwr; j++) acc += s->B_pinv[i * s->nwr + j] * body[s->wrench_rows[j]];
    int sat = acc < s->lo[i] || acc > s->hi[i];
    s->sat[i] = sat;
    s->thrust[i] = acc < s->lo[i] ? s->lo[i] : (acc > s->hi[i] ? s->hi[i] : acc);
  }
  return 0;
}

// The achieved base force, the observers (Eq. 14 corrected, Fig. 3(b)), torques, next state.
int uvms_rac_finish(uvms_rac* s) {
  int nv = s->nv, nt = s->ntask, na = s->na, nb = s->nb;
  const double* Rb = s->R_base;
  const double* M = s->M;
  const int *b = s->base_dofs, *a = s->arm_dofs;
  double prod[6];
  for (int i = 0; i < 6; i++) {  // B f, body axes
    double acc = 0.0;
    for (int j = 0; j < s->nthr; j++) acc += s->B[i * s->nthr + j] * s->thrust[j];
    prod[i] = acc;
  }
  if (s->free_base) {
    for (int i = 0; i < 3; i++) {
      s->u_app[i] = Rb[3 * i] * prod[0] + Rb[3 * i + 1] * prod[1] + Rb[3 * i + 2] * prod[2];
      s->u_app[3 + i] = prod[3 + i];
    }
  } else {
    double w[6];
    for (int i = 0; i < 3; i++) {
      w[i] = Rb[3 * i] * prod[0] + Rb[3 * i + 1] * prod[1] + Rb[3 * i + 2] * prod[2];
      w[3 + i] = Rb[3 * i] * prod[3] + Rb[3 * i + 1] * prod[4] + Rb[3 * i + 2] * prod[5];
    }
    for (int j = 0; j < nb; j++) {  // Jb^T w
      double acc = 0.0;
      for (int i = 0; i < 6; i++) acc += s->Jb[i * nb + j] * w[i];
      s->u_app[j] = acc;
    }
  }
  if (s->observer) {  // w = u_B - f_t + g M_BB x0_dot; z(k+1) = h z + (1 - h) w
    const double* applied = s->alloc_input ? s->u_app : s->u_B;
    for (int i = 0; i < nb; i++) {
      double qacc = 0.0;
      for (int j = 0; j < nb; j++) qacc += M[b[i] * nv + b[j]] * s->qd[b[j]];
      double w = applied[i] - s->f_t[i] + s->g * qacc;
      s->z[i] = s->h * s->z[i] + (1.0 - s->h) * w;
    }
  }
  if (s->observer_arm) {  // the same on the arm rows, with the torques the motors can give
    double tau[MAXN];
    mju_copy(tau, s->u_M, na);
    for (int k = 0; k < s->nmot; k++) {
      int i = s->motor_idx[k];
      double v = s->u_M[i];
      tau[i] = v < s->motor_lo[k] ? s->motor_lo[k] : (v > s->motor_hi[k] ? s->motor_hi[k] : v);
    }
    for (int i = 0; i < na; i++) {
      double qacc = 0.0;
      for (int j = 0; j < na; j++) qacc += M[a[i] * nv + a[j]] * s->qd[a[j]];
      double w = tau[i] - s->f_tM[i] + s->g_arm * qacc;
      s->z_arm[i] = s->h_arm * s->z_arm[i] + (1.0 - s->h_arm) * w;
    }
  }
  for (int k = 0; k < s->nmot; k++) {  // inside the motors' ranges
    double v = s->u_M[s->motor_idx[k]];
    s->torques[k] = v < s->motor_lo[k] ? s->motor_lo[k] : (v > s->motor_hi[k] ? s->motor_hi[k] : v);
  }
  if (s->free_base) mju_mat2Quat(s->base_quat, s->Rd);
  // the state for the next sample (its p_d(k) is this one's p_d(k + 1))
  mju_copy(s->pd_out, s->pd, s->nvec);
  mju_copy(s->pd_prev, s->pd, s->nvec);
  mju_copy(s->Rd_prev, s->Rd, 18);
  mju_copy(s->pd, s->pdn, s->nvec);
  mju_copy(s->Rd, s->Rdn, 18);
  mju_copy(s->e_p_prev, s->e_p, nt);
  mju_copy(s->q_prev, s->q, s->nq);
  mju_copy(s->p_prev, s->p, s->nvec);
  mju_copy(s->R_prev, s->R, 18);
  mju_copy(s->J_prev, s->J, nt * nv);
  return 0;
}
