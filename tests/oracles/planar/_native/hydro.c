/*
 * The planar closed-form hydrodynamics of the paper's robot in C: a line-by-line port of
 * HydroModel.evaluate() in src/uvms_mj/planar/hydro.py, used by the controller's nominal model
 * (uvms_mj.planar.nominal) for speed. The PLANT's hydrodynamics are the MuJoCo plugins in
 * src/uvms_mj/physics/plugin/ (any robot); this file serves only the planar nominal model.
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
 * ._bodies) through uvms_params, whose layout is mirrored by uvms_mj.planar.native.Params.
 */

#include <math.h>
#include <stddef.h>


#define UVMS_NV 5            /* q = (p0x, p0y, phi0, phi1, phi2) */
#define UVMS_NM 15           /* lower triangle of the 5x5 mass matrix */
#define UVMS_MAXBODY 3       /* base, link1, link2 */
#define UVMS_NB 16           /* constants per body, as in HydroModel._bodies */

/* Parameters of one model. Mirrored by uvms_mj.planar.native.Params (ctypes): keep the two in the
 * same order. */
typedef struct {
  /* Per body, in chain order, exactly HydroModel._bodies:
   * jx, jy, cx, cy, mx, my, ia, kx, ky, xa, xb, ya, yb, rhov, bx, by */
  double bodies[UVMS_MAXBODY * UVMS_NB];
  int nbody;
  int exact;              /* added mass "exact": matrix into d->M, velocity terms */
  int strip;              /* drag "strip" */
  int buoyancy;           /* buoyancy on */
} uvms_params;

/* Layout check for the ctypes mirror: sizeof(uvms_params) and the offsets of its fields
 * nbody, exact, buoyancy (4 numbers). */
void uvms_params_layout(size_t* out) {
  out[0] = sizeof(uvms_params);
  out[1] = offsetof(uvms_params, nbody);
  out[2] = offsetof(uvms_params, exact);
  out[3] = offsetof(uvms_params, buoyancy);
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
