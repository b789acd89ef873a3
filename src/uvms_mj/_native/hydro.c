/*
 * Native hydrodynamics of the uvms_mj plant: a line-by-line C port of
 * HydroModel.evaluate() in src/uvms_mj/hydro.py (the pure-Python reference, which stays the
 * ground truth and the fallback) plus a MuJoCo mjcb_passive callback that applies it.
 *
 * Same maths, same formulas, same order of floating-point operations (compiled without
 * -ffast-math and with -ffp-contract=off, so results match the Python reference to the last
 * bit or nearly so):
 *
 *   - Added mass and added inertia (exact): Kirchhoff/Munk velocity terms, the J_dot (bias
 *     acceleration) term, and the added-mass matrix sum_b J_b^T D_b J_b that goes into d->M.
 *   - Drag by strip theory (paper Eqs. 2-3): closed-form int |w| w ds and int s |w| w ds for a
 *     linear normal velocity, split at the sign change, never dividing by omega.
 *   - Buoyancy (paper Eqs. 4-5): -rho V g at each centre of buoyancy.
 *
 * No model numbers live here: every constant comes from Python (RobotParams -> HydroModel
 * ._bodies) through uvms_params, whose layout is mirrored by uvms_mj.native.Params.
 *
 * The callback. MuJoCo has one process-global mjcb_passive. uvms_passive() looks the mjData
 * up in a small lock-free registry of (mjData*, uvms_params*) pairs filled from Python:
 *   - registered data: divergence check (records a status in its uvms_params and leaves d
 *     alone), exact added mass into d->M + mj_factorM (guarded against mj_forwardSkip
 *     re-entering with d->M already augmented), forces into d->qfrc_passive;
 *   - any other data: calls the fallback (the Python ctypes dispatcher of uvms_mj.plant,
 *     which serves Python-backed plants and warns about unregistered data of plant models).
 * Wind (water current) and gravity are read from m->opt on every call.
 */

#include <math.h>
#include <stddef.h>

#include <mujoco/mujoco.h>

#define UVMS_NV 5            /* q = (p0x, p0y, phi0, phi1, phi2) */
#define UVMS_NM 15           /* lower triangle of the 5x5 mass matrix */
#define UVMS_MAXBODY 3       /* base, link1, link2 */
#define UVMS_NB 16           /* constants per body, as in HydroModel._bodies */
#define UVMS_MAXDATA 4096    /* registry capacity (live registered mjData) */

/* Divergence status (uvms_params.status). */
#define UVMS_OK 0
#define UVMS_RUNAWAY 1
#define UVMS_NONFINITE 2

/* Parameters and per-data state of one registered mjData. Mirrored by
 * uvms_mj.native.Params (ctypes): keep the two in the same order. */
typedef struct {
  /* Per body, in chain order, exactly HydroModel._bodies:
   * jx, jy, cx, cy, mx, my, ia, kx, ky, xa, xb, ya, yb, rhov, bx, by */
  double bodies[UVMS_MAXBODY * UVMS_NB];
  int nbody;
  int exact;              /* added mass "exact": matrix into d->M, velocity terms */
  int strip;              /* drag "strip" */
  int buoyancy;           /* buoyancy on */
  double max_speed;       /* runaway threshold on sum |qd| */
  /* state, written by the callback */
  int augmented_valid;    /* augmented holds a value */
  double augmented;       /* d->M[0] right after the last augmentation */
  int status;             /* UVMS_OK / UVMS_RUNAWAY / UVMS_NONFINITE (first one kept) */
  double status_time;     /* d->time when status was set */
  double status_speed;    /* sum |qd| then (for the message) */
} uvms_params;

/* Layout check for the ctypes mirror: sizeof(uvms_params) and the offsets of its fields
 * nbody, max_speed, augmented, status, status_time, status_speed (7 numbers). */
void uvms_params_layout(size_t* out) {
  out[0] = sizeof(uvms_params);
  out[1] = offsetof(uvms_params, nbody);
  out[2] = offsetof(uvms_params, max_speed);
  out[3] = offsetof(uvms_params, augmented);
  out[4] = offsetof(uvms_params, status);
  out[5] = offsetof(uvms_params, status_time);
  out[6] = offsetof(uvms_params, status_speed);
}

/* ------------------------------------------------------------------ strip integrals */

/* int_a^b w^2 ds and int_a^b s w^2 ds for w = w0 + om s (no sign): hydro._poly_piece. */
static void poly_piece(double w0, double om, double a, double b, double* r0, double* r1) {
  double a2 = a * a, b2 = b * b;
  double a3 = a2 * a, b3 = b2 * b;
  double d1 = b - a, d2 = b2 - a2, d3 = b3 - a3, d4 = b2 * b2 - a2 * a2;
  double w02 = w0 * w0, wom = w0 * om, om2 = om * om;
  *r0 = w02 * d1 + wom * d2 + om2 * d3 / 3.0;
  *r1 = 0.5 * w02 * d2 + (2.0 / 3.0) * wom * d3 + 0.25 * om2 * d4;
}

/* Paper Eqs. 2-3: (int_a^b |w| w ds, int_a^b s |w| w ds), w(s) = w0 + om s, a <= b.
 * hydro.strip_integrals: split at s* = -w0/om only when strictly inside; no division by om
 * otherwise. */
void uvms_strip_integrals(double w0, double om, double a, double b, double* out0, double* out1) {
  double i0, i1, j0, j1;
  if (om != 0.0) {
    double s0 = -w0 / om;
    if (a < s0 && s0 < b) {
      poly_piece(w0, om, a, s0, &i0, &i1);
      poly_piece(w0, om, s0, b, &j0, &j1);
      double sa = (w0 + om * a > 0) ? 1.0 : -1.0;
      *out0 = sa * (i0 - j0);
      *out1 = sa * (i1 - j1);
      return;
    }
  }
  double wm = w0 + om * 0.5 * (a + b);
  if (wm == 0.0) {
    *out0 = 0.0;
    *out1 = 0.0;
    return;
  }
  poly_piece(w0, om, a, b, &i0, &i1);
  if (wm > 0) {
    *out0 = i0;
    *out1 = i1;
  } else {
    *out0 = -i0;
    *out1 = -i1;
  }
}

/* ------------------------------------------------------------------ evaluation */

/* HydroModel.evaluate: added-mass matrix (lower triangle, 15, row-major (0,0),(1,0),(1,1),
 * (2,0)...) ADDED to M when M != NULL and the added mass is exact, and the generalized force
 * (5) WRITTEN to Q. wind, gravity: world (x, y). Comments follow hydro.py. */
void uvms_evaluate(const uvms_params* p, const double* q, const double* qd, const double* wind,
                   const double* gravity, double* M, double* Q) {
  const int exact_am = p->exact, strip = p->strip, buoy = p->buoyancy;
  const double wx = wind[0], wy = wind[1];
  const double gx = gravity[0], gy = gravity[1];
  if (!exact_am) M = NULL;

  for (int k = 0; k < UVMS_NV; k++) Q[k] = 0.0;
  /* Running chain state: origin o of the current body, its velocity and its acceleration at
   * q_ddot = 0 (world frame); absolute angle th and angular velocity w. */
  double ox = q[0], oy = q[1];
  double ovx = qd[0], ovy = qd[1];
  double oax = 0.0, oay = 0.0, th = 0.0, w = 0.0, s = 0.0;
  double c = 1.0;
  double pvx[UVMS_MAXBODY], pvy[UVMS_MAXBODY]; /* pivot (hinge) positions o_k, world */
  int nbody = p->nbody < UVMS_MAXBODY ? p->nbody : UVMS_MAXBODY;

  for (int i = 0; i < nbody; i++) {
    const double* bp = p->bodies + i * UVMS_NB;
    const double jx = bp[0], jy = bp[1], cx = bp[2], cy = bp[3], mx = bp[4], my = bp[5],
                 ia = bp[6], kx = bp[7], ky = bp[8], xa = bp[9], xb = bp[10], ya = bp[11],
                 yb = bp[12], rhov = bp[13], bx = bp[14], by = bp[15];
    if (i) {
      /* Move to this body's origin along the parent (still the parent's angle). */
      double dx = c * jx - s * jy;
      double dy = s * jx + c * jy;
      ox += dx;
      oy += dy;
      ovx -= w * dy;
      ovy += w * dx;
      oax -= w * w * dx;
      oay -= w * w * dy;
    }
    th += q[2 + i];
    w += qd[2 + i];
    c = cos(th);
    s = sin(th);
    pvx[i] = ox;
    pvy[i] = oy;
    double fx = 0.0, fy = 0.0, tq = 0.0; /* world force and torque about o on this body */
    double fbx, fby;
    /* Body-frame velocity of the origin relative to the water. */
    double rvx = ovx - wx;
    double rvy = ovy - wy;
    double ubx = c * rvx + s * rvy;
    double uby = c * rvy - s * rvx;

    if (exact_am) {
      /* Added mass (Kirchhoff/Munk + J_dot term). Reference point p = o + R (cx, cy); its
       * velocity and q_ddot = 0 acceleration in the body frame. */
      double vbx = ubx - w * cy;
      double vby = uby + w * cx;
      double abx = c * oax + s * oay - w * w * cx;
      double aby = c * oay - s * oax - w * w * cy;
      double dm = my - mx;
      fbx = dm * w * vby - mx * abx;
      fby = dm * w * vbx - my * aby;
      double fwx = c * fbx - s * fby;
      double fwy = s * fbx + c * fby;
      double rx = c * cx - s * cy;
      double ry = s * cx + c * cy;
      fx += fwx;
      fy += fwy;
      tq += rx * fwy - ry * fwx - dm * vbx * vby; /* + Munk moment (m_Ax - m_Ay) v_x v_y */
      if (M) {
        /* A = R diag(mx, my) R^T; column of hinge k at p: u_k = perp(p - o_k). */
        double cc = c * c, ss = s * s, cs = c * s;
        double axx = mx * cc + my * ss;
        double ayy = mx * ss + my * cc;
        double axy = -dm * cs;
        double px = ox + rx;
        double py = oy + ry;
        M[0] += axx;
        M[1] += axy;
        M[2] += ayy;
        int r = 3;
        for (int k = 0; k <= i; k++) {
          double ukx = pvy[k] - py;
          double uky = px - pvx[k];
          double aux = axx * ukx + axy * uky;
          double auy = axy * ukx + ayy * uky;
          M[r] += aux;
          M[r + 1] += auy;
          for (int j = 0; j <= k; j++) {
            M[r + 2 + j] += (pvy[j] - py) * aux + (px - pvx[j]) * auy + ia;
          }
          r += k + 3;
        }
      }
    }

    if (strip) {
      /* Strip drag, paper Eqs. 2-3. */
      double i0, i1;
      if (ky != 0.0) { /* flow along body y; strips over x in [xa, xb]: w(x) = uby + w x */
        uvms_strip_integrals(uby, w, xa, xb, &i0, &i1);
        fbx = 0.0;
        fby = -ky * i0;
        tq -= ky * i1;
      } else {
        fbx = fby = 0.0;
      }
      if (kx != 0.0) { /* flow along body x; strips over y in [ya, yb]: w(y) = ubx - w y */
        uvms_strip_integrals(ubx, -w, ya, yb, &i0, &i1);
        fbx = -kx * i0;
        tq += kx * i1;
      }
      fx += c * fbx - s * fby;
      fy += s * fbx + c * fby;
    }

    if (buoy && rhov != 0.0) {
      /* Buoyancy, paper Eqs. 4-5: -rho V g at the centre of buoyancy. */
      fbx = -rhov * gx;
      fby = -rhov * gy;
      fx += fbx;
      fy += fby;
      tq += (c * bx - s * by) * fby - (s * bx + c * by) * fbx;
    }

    /* Generalized force of the wrench (fx, fy; tq about o) on the chain: J^T at o. */
    Q[0] += fx;
    Q[1] += fy;
    for (int k = 0; k <= i; k++) {
      Q[2 + k] += tq + (ox - pvx[k]) * fy - (oy - pvy[k]) * fx;
    }
  }
}

/* ------------------------------------------------------------------ registry */

/* Slot i is free when p == NULL. Claimed by CAS on p, published by storing d (release), so a
 * lookup that sees d also sees p; cleared d first, then p. Lock-free: unregister may be
 * called from a Python finalizer (garbage collector) at any time. */
typedef struct {
  mjData* d;
  uvms_params* p;
} uvms_slot;

static uvms_slot registry[UVMS_MAXDATA];
static int registry_high = 0; /* slots [0, registry_high) may be in use */
static mjfGeneric fallback = NULL;

/* Register data d with its parameters p (kept alive by the caller until unregistered).
 * Returns the slot index, or -1 when the registry is full. */
int uvms_register(mjData* d, uvms_params* p) {
  for (int i = 0; i < UVMS_MAXDATA; i++) {
    uvms_params* expected = NULL;
    if (__atomic_compare_exchange_n(&registry[i].p, &expected, p, 0, __ATOMIC_ACQ_REL,
                                    __ATOMIC_RELAXED)) {
      __atomic_store_n(&registry[i].d, d, __ATOMIC_RELEASE);
      int high = __atomic_load_n(&registry_high, __ATOMIC_ACQUIRE);
      while (high < i + 1 &&
             !__atomic_compare_exchange_n(&registry_high, &high, i + 1, 0, __ATOMIC_ACQ_REL,
                                          __ATOMIC_ACQUIRE)) {
      }
      return i;
    }
  }
  return -1;
}

/* Unregister data d (no-op if it is not registered). Returns 1 if it was. */
int uvms_unregister(mjData* d) {
  int high = __atomic_load_n(&registry_high, __ATOMIC_ACQUIRE);
  for (int i = 0; i < high; i++) {
    if (__atomic_load_n(&registry[i].d, __ATOMIC_ACQUIRE) == d) {
      __atomic_store_n(&registry[i].d, NULL, __ATOMIC_RELEASE);
      __atomic_store_n(&registry[i].p, NULL, __ATOMIC_RELEASE);
      return 1;
    }
  }
  return 0;
}

/* Number of registered data (for tests). */
int uvms_registered_count(void) {
  int n = 0, high = __atomic_load_n(&registry_high, __ATOMIC_ACQUIRE);
  for (int i = 0; i < high; i++) {
    if (__atomic_load_n(&registry[i].d, __ATOMIC_ACQUIRE) != NULL) n++;
  }
  return n;
}

/* The callback for data that is not registered here (NULL: none). */
void uvms_set_fallback(mjfGeneric f) {
  __atomic_store_n(&fallback, f, __ATOMIC_RELEASE);
}

static uvms_params* lookup(const mjData* d) {
  int high = __atomic_load_n(&registry_high, __ATOMIC_ACQUIRE);
  for (int i = 0; i < high; i++) {
    if (__atomic_load_n(&registry[i].d, __ATOMIC_ACQUIRE) == d) {
      return __atomic_load_n(&registry[i].p, __ATOMIC_ACQUIRE); /* NULL if just cleared */
    }
  }
  return NULL;
}

/* ------------------------------------------------------------------ the callback */

/* Mirrors the passive() handler of Plant._attach (plant.py). */
void uvms_passive(const mjModel* m, mjData* d) {
  uvms_params* p = lookup(d);
  if (!p) {
    mjfGeneric f = __atomic_load_n(&fallback, __ATOMIC_ACQUIRE);
    if (f) f(m, d);
    return;
  }
  if (m->nv != UVMS_NV || m->nC != UVMS_NM) return; /* not the planar chain (cannot happen) */

  const double* q = d->qpos;
  const double* qd = d->qvel;
  /* One sum catches NaN, inf and runaway speeds (a NaN makes the comparison false). */
  double speed = 0.0, qsum = 0.0;
  for (int k = 0; k < UVMS_NV; k++) {
    speed += fabs(qd[k]);
    qsum += q[k];
  }
  if (!(speed <= p->max_speed && isfinite(qsum))) {
    if (p->status == UVMS_OK) { /* record the first divergence; a callback cannot raise */
      int finite = 1;
      for (int k = 0; k < UVMS_NV; k++) finite = finite && isfinite(q[k]) && isfinite(qd[k]);
      p->status_time = d->time;
      p->status_speed = speed;
      p->status = finite ? UVMS_RUNAWAY : UVMS_NONFINITE;
    }
    return;
  }

  double wind[2] = {m->opt.wind[0], m->opt.wind[1]};
  double gravity[2] = {m->opt.gravity[0], m->opt.gravity[1]};
  double Q[UVMS_NV];
  double madd[UVMS_NM] = {0.0};
  /* mj_forwardSkip (finite differencing) re-enters here with d->M already augmented. */
  int want_mass = p->exact && !(p->augmented_valid && p->augmented == d->M[0]);
  uvms_evaluate(p, q, qd, wind, gravity, want_mass ? madd : NULL, Q);
  if (want_mass) {
    /* The mass matrix of the planar chain is dense (checked by Plant): its CSR lower
     * triangle is exactly the 15-vector. Summed first, then added, as in plant.py. */
    for (int k = 0; k < UVMS_NM; k++) d->M[k] += madd[k];
    mj_factorM(m, d);
    p->augmented = d->M[0];
    p->augmented_valid = 1;
  }
  for (int k = 0; k < UVMS_NV; k++) d->qfrc_passive[k] += Q[k];
}
