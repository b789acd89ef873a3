/*
 * MuJoCo engine plugins `uvms.water` and `uvms.hydro`: hydrodynamics of underwater robots.
 *
 * The specification is docs/hydrodynamics.md (attributes, defaults, frames, Fossen's order,
 * equations 1-6, the current models, the guard); uvms_mj.physics.reference is the numpy
 * implementation of the same equations. Compiled together with the other C files of
 * physics/plugin into one shared library by uvms_mj.physics.build (-O2 -ffp-contract=off).
 *
 * uvms.hydro (one instance per body, inside <body>): carries that body's parameters only
 *   (capability passive, compute does nothing, no state). Its init only checks that the model
 *   has a uvms.water instance and that the instance is attached to a body.
 *
 * uvms.water (one model-level instance, under <extension>): does all the work. Its wave_*
 *   and surface attributes are parsed here (parse_waves) and the waves computed in waves.c.
 *   init:    finds every body whose body_plugin is a uvms.hydro instance, parses and validates
 *            every config (errors: mju_error with a one-line message naming the body, the
 *            attribute, the value and what is allowed; from Python this is a ValueError at
 *            compile time or mujoco.FatalError from MjData(), never a crash), resolves the
 *            defaults (pos = body_ipos, cob = pos), checks that the rows of the sparse d->M of
 *            every body with added mass hold all its ancestor dofs (refusing "simple" bodies),
 *            caches the bodies and dofs involved, and allocates the per-mjData plugin data
 *            (parameters, guard copy of d->M, per-body scratch): no mallocs in compute and no
 *            global mutable state (mujoco.rollout threads). A model with uvms.hydro bodies but
 *            no uvms.water instance, or with two uvms.water instances, is refused likewise.
 *   compute: (passive stage) for every body, at the origin p of its frame h (R its world
 *            orientation), with J = [R^T Jp(p); R^T Jr] (Fossen's order) and
 *            nu_r = J qvel - (R^T v_c(p, t), 0):
 *            1. added mass: d->M += J^T M_A J, then mj_factorM and, when d->nefc > 0,
 *               mj_projectConstraint. Guarded: added only if d->M differs in any entry from
 *               the copy of the last augmented d->M (mj_forwardSkip re-enters with d->M
 *               already augmented); then the new augmented d->M is copied;
 *            2. tau_A = [h_v x w; h_v x v_r + h_w x w] - M_A a + M_A [R^T a_c; 0], h = M_A nu_r,
 *               a = [R^T Jp_dot qvel - w x v_r; R^T Jr_dot qvel];
 *            3. tau_D = -(D_L + D_Q |nu_r|) nu_r;
 *            4. strips: closed-form integrals of |w_n| w_n and s |w_n| w_n (strip_integrals);
 *            5. buoyancy -rho V g and 6. Froude-Krylov rho V a_c, both at the centre of
 *               buoyancy (moved to p as a force plus the moment (cob - p) x F);
 *            waves (waves.c, when wave_model is not none): v_c and a_c at p gain the waves'
 *            particle velocity and local acceleration at p; each strip sees the waves at its
 *            midpoint instead (plus the current at p);
 *            qfrc_passive += J^T (tau_A + tau_D + tau_strip at p; forces at cob), which is what
 *            mj_applyFT computes.
 *            How (same maths, without mj_jac, mj_jacDot or mj_applyFT, which zero and fill
 *            3 x nv arrays per call): MuJoCo's motion axes cdof (with cdof_dot, cvel and
 *            subtree_com, what mj_jac and mj_jacDot are made of) give per body nu (its cvel moved
 *            to p), J_dot qvel (a forward pass summing qvel cdof_dot along the tree, ball and
 *            free rotations handled as mj_jacDot does), the columns of J over the body's dof
 *            chain (for J^T M_A J, added to the rows of the chain: the CSR row of chain[a]
 *            holds exactly chain[0..a]), and the generalized forces by subtree sums of spatial
 *            forces (a backward pass as in MuJoCo's RNE): qfrc_i += cdof_i . sum_{b below i} F_b
 *            with F_b = (t + (p - com) x f, f) for the world force f and torque t about p.
 *            tests/test_plugin_c.py checks both against mj_jac, mj_jacDot and mj_applyFT.
 *   advance: (after each mj_step, every integrator: MuJoCo's mj_advance, which Euler,
 *            implicit, implicitfast and RK4 (once, at the end of its 4 stages) all call)
 *            shifts the Gauss-Markov sample.
 *
 * Plugin state of uvms.water (nstate = 9, d->plugin_state + m->plugin_stateadr[instance]):
 *   [0] t_k      time of sample k (the start of the current sample interval)
 *   [1] k        sample index (an integer stored as a double)
 *   [2..4] v_k   current at t_k (world, m/s)
 *   [5..7] v_n   current at t_k + h (the sample k + 1)
 *   [8] h        length of the interval (m->opt.timestep when v_n was drawn)
 * reset: t_k = 0, k = 0, v_k = `current`, h = timestep; v_n = v_k (constant, profile) or the
 *   first Ornstein-Uhlenbeck draw v_1 from v_0 = `current` with n_0 (gauss_markov; v_0 itself
 *   is not clipped). advance (gauss_markov only): t_k = d->time, k += 1, v_k = v_n,
 *   h = timestep, v_n = draw(v_k, k, h). Between samples the current is
 *   v_k + clamp((t - t_k)/h, 0, 1) (v_n - v_k) with a_c = (v_n - v_k)/h (RK4's stages see
 *   t_k, t_k + h/2 and t_k + h). constant: v_c = v_k (the user may overwrite state[2..7] to
 *   change it at run time), a_c = 0; profile: v_c(z) from the knots, a_c = 0.
 *
 * The draw (reproduced bit for bit by the Python reference):
 *   e1 = exp((-h) / tau), e2 = exp((-2.0 * h) / tau)
 *   v = mu + (v_k - mu) * e1 + sigma * sqrt(1.0 - e2) * n_k,c; then clipped to [min, max]
 *   n_k,c: splitmix64 counter-based Box-Muller normal of (gm_seed, k, c), see gm_normal().
 */

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

#include "waves.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* ------------------------------------------------------------------ attributes */

static const char* const water_attributes[] = {
    "density", "current", "current_model", "gm_mean", "gm_sigma", "gm_tau",
    "gm_min",  "gm_max",  "gm_seed",       "profile", "terms",
    /* waves (waves.c; docs/hydrodynamics.md "Waves"), appended: m->plugin_attr keeps this order */
    "wave_model", "wave_height", "wave_period", "wave_gamma", "wave_direction", "wave_spreading",
    "wave_depth", "surface", "wave_seed", "wave_components"};
#define WATER_NATTR ((int)(sizeof(water_attributes) / sizeof(water_attributes[0])))

static const char* const hydro_attributes[] = {"pos",               "quat",   "added_mass",
                                               "linear_damping",    "quadratic_damping",
                                               "strips",            "volume", "cob"};
#define HYDRO_NATTR ((int)(sizeof(hydro_attributes) / sizeof(hydro_attributes[0])))

#define WATER_NSTATE 9

enum { TERM_ADDED_MASS = 1, TERM_DAMPING = 2, TERM_STRIPS = 4, TERM_BUOYANCY = 8,
       TERM_FROUDE_KRYLOV = 16, TERM_ALL = 31 };
static const char* const term_words[] = {"added_mass", "damping", "strips", "buoyancy",
                                         "froude_krylov"};

enum { CURRENT_CONSTANT = 0, CURRENT_GAUSS_MARKOV = 1, CURRENT_PROFILE = 2 };

/* ------------------------------------------------------------------ data */

typedef struct {
  int axis;                  /* 0, 1, 2: x, y, z of h */
  double s0, s1, cd[2];      /* extent along the axis; C_D D for the two other axes, in order */
} strip_t;

typedef struct {
  int body;
  double pos[3];             /* origin of h, body frame */
  double quat[4];            /* orientation of h, body frame (normalised) */
  double hmat[9];            /* its rotation matrix */
  int hident;                /* quat is the identity: R = xmat */
  double cob[3];             /* centre of buoyancy, body frame */
  double MA[36];             /* added mass, row-major, Fossen's order */
  int has_am, diag_am;       /* M_A has a nonzero entry; M_A is diagonal */
  double DL[6], DQ[6];
  int has_damp;
  int nstrip;
  strip_t* strips;
  double volume;
  int nc;                    /* dofs that move the body (its chain, increasing) */
  int* chain;
} hbody_t;

typedef struct {
  int instance;
  /* uvms.water config */
  double rho, current[3];
  int model;
  double mean[3], sigma[3], tau[3], vmin[3], vmax[3];
  uint64_t seed;
  int nknot;
  double* knots;             /* z vx vy vz per knot */
  int terms;
  waves_params_t wave;       /* the waves' config (waves.h) */
  waves_t waves;             /* their components (n = 0: no waves) */
  /* bodies */
  int nbody;
  hbody_t* bodies;
  int any_am;
  /* per-mjData */
  int nv, nC;
  double* Mcopy;             /* the augmented d->M of the last augmentation (guard) */
  int Mvalid;
  int nactive;               /* bodies with uvms.hydro and their ancestors (dofs only), increasing */
  int* active;
  int nfdof;                 /* dofs moving a uvms.hydro body, increasing */
  int* fdof;
  unsigned char* dof_quat;   /* per dof: rotation of a ball or free joint (cdof_dot from cvel) */
  double *Fb, *Bb;           /* per body: 6, 6 (compute scratch) */
  int maxnc;
  double *J, *W;             /* 6 x maxnc each (compute scratch) */
} water_t;

/* ------------------------------------------------------------------ counter-based normals */

/* Standard normal number k, component c (0, 1, 2) of the stream `seed`. */
static double gm_normal(uint64_t seed, uint64_t k, int c) {
  uint64_t i = 6 * k + 2 * (uint64_t)c;
  uint64_t a = uvms_splitmix64(seed ^ uvms_splitmix64(i));
  uint64_t b = uvms_splitmix64(seed ^ uvms_splitmix64(i + 1));
  double u1 = (double)((a >> 11) + 1) * 0x1p-53;
  double u2 = (double)(b >> 11) * 0x1p-53;
  return sqrt(-2.0 * log(u1)) * cos(2.0 * M_PI * u2);
}

/* Exported for tests (Python reproduces it bit for bit). */
double uvms_water_gm_normal(uint64_t seed, uint64_t k, int c) { return gm_normal(seed, k, c); }

/* v_{k+1} from v_k with the noise of sample k, interval h. */
static void gm_draw(const water_t* w, const double vk[3], uint64_t k, double h, double out[3]) {
  for (int c = 0; c < 3; c++) {
    double e1 = exp((-h) / w->tau[c]);
    double e2 = exp((-2.0 * h) / w->tau[c]);
    double n = gm_normal(w->seed, k, c);
    double v = w->mean[c] + (vk[c] - w->mean[c]) * e1 + w->sigma[c] * sqrt(1.0 - e2) * n;
    if (v < w->vmin[c]) v = w->vmin[c];
    if (v > w->vmax[c]) v = w->vmax[c];
    out[c] = v;
  }
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

/* (int_a^b |w| w ds, int_a^b s |w| w ds), w(s) = w0 + om s, a <= b (hydro.strip_integrals):
 * split at s* = -w0/om only when strictly inside; never divides by om otherwise. */
static void strip_integrals(double w0, double om, double a, double b, double* out0,
                            double* out1) {
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

/* Exported for tests. */
void uvms_water_strip_integrals(double w0, double om, double a, double b, double* out0,
                                double* out1) {
  strip_integrals(w0, om, a, b, out0, out1);
}

/* ------------------------------------------------------------------ small linear algebra */

static inline void cross3(double r[3], const double a[3], const double b[3]) {
  double x = a[1] * b[2] - a[2] * b[1];
  double y = a[2] * b[0] - a[0] * b[2];
  double z = a[0] * b[1] - a[1] * b[0];
  r[0] = x;
  r[1] = y;
  r[2] = z;
}

/* r = R^T v (R row-major 3x3) */
static inline void mulT3(double r[3], const double R[9], const double v[3]) {
  double x = R[0] * v[0] + R[3] * v[1] + R[6] * v[2];
  double y = R[1] * v[0] + R[4] * v[1] + R[7] * v[2];
  double z = R[2] * v[0] + R[5] * v[1] + R[8] * v[2];
  r[0] = x;
  r[1] = y;
  r[2] = z;
}

/* r = R v */
static inline void mul3(double r[3], const double R[9], const double v[3]) {
  double x = R[0] * v[0] + R[1] * v[1] + R[2] * v[2];
  double y = R[3] * v[0] + R[4] * v[1] + R[5] * v[2];
  double z = R[6] * v[0] + R[7] * v[1] + R[8] * v[2];
  r[0] = x;
  r[1] = y;
  r[2] = z;
}

/* Eigenvalues of a symmetric 6x6 matrix (cyclic Jacobi), smallest returned. */
static double min_eig6(const double A[36]) {
  double a[36];
  memcpy(a, A, sizeof(a));
  for (int i = 0; i < 6; i++)
    for (int j = 0; j < i; j++) a[6 * i + j] = a[6 * j + i] = 0.5 * (A[6 * i + j] + A[6 * j + i]);
  for (int sweep = 0; sweep < 100; sweep++) {
    double off = 0.0, tot = 0.0;
    for (int i = 0; i < 6; i++)
      for (int j = 0; j < 6; j++) {
        tot += a[6 * i + j] * a[6 * i + j];
        if (i != j) off += a[6 * i + j] * a[6 * i + j];
      }
    if (off <= 1e-30 * tot || off == 0.0) break;
    for (int p = 0; p < 5; p++)
      for (int q = p + 1; q < 6; q++) {
        double apq = a[6 * p + q];
        if (apq == 0.0) continue;
        double theta = (a[6 * q + q] - a[6 * p + p]) / (2.0 * apq);
        double t = (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
        double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
        for (int k = 0; k < 6; k++) { /* columns p, q */
          double akp = a[6 * k + p], akq = a[6 * k + q];
          a[6 * k + p] = c * akp - s * akq;
          a[6 * k + q] = s * akp + c * akq;
        }
        for (int k = 0; k < 6; k++) { /* rows p, q */
          double apk = a[6 * p + k], aqk = a[6 * q + k];
          a[6 * p + k] = c * apk - s * aqk;
          a[6 * q + k] = s * apk + c * aqk;
        }
      }
  }
  double mn = a[0];
  for (int i = 1; i < 6; i++)
    if (a[7 * i] < mn) mn = a[7 * i];
  return mn;
}

/* ------------------------------------------------------------------ parsing */

typedef struct {
  char msg[900];
  int failed;
} err_t;

static void fail(err_t* e, const char* fmt, ...) __attribute__((format(printf, 2, 3)));
static void fail(err_t* e, const char* fmt, ...) {
  if (e->failed) return;
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(e->msg, sizeof(e->msg), fmt, ap);
  va_end(ap);
  e->failed = 1;
}

/* a printable, shortened copy of a config value for messages */
static const char* shown(const char* v, char* buf, size_t n) {
  size_t len = strlen(v);
  if (len + 1 <= n) return v;
  snprintf(buf, n, "%.*s...", (int)(n - 4), v);
  return buf;
}

static int is_space(char c) {
  return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f';
}

/* Parse whitespace-separated numbers of s[0:len] into out (at most maxn). Returns the count,
 * or -1 (a token that is not a number; *bad = its index) or -2 (a number that is not finite). */
static int parse_numbers(const char* s, size_t len, double* out, int maxn, int* bad) {
  int n = 0;
  size_t i = 0;
  char tok[128];
  while (i < len) {
    while (i < len && is_space(s[i])) i++;
    if (i >= len) break;
    size_t j = i;
    while (j < len && !is_space(s[j])) j++;
    size_t tl = j - i;
    if (tl >= sizeof(tok)) {
      *bad = n;
      return -1;
    }
    memcpy(tok, s + i, tl);
    tok[tl] = 0;
    char* end;
    double v = strtod(tok, &end);
    if (end == tok || *end) {
      *bad = n;
      return -1;
    }
    if (!isfinite(v)) {
      *bad = n;
      return -2;
    }
    if (n < maxn) out[n] = v;
    n++;
    i = j;
  }
  return n;
}

/* Value of a config attribute; NULL if unset (absent or empty). */
static const char* config(const mjModel* m, int instance, const char* key) {
  const char* v = mj_getPluginConfig(m, instance, key);
  if (!v) return NULL;
  for (const char* p = v; *p; p++)
    if (!is_space(*p)) return v;
  return NULL;
}

/* Read exactly one of the counts in `counts` (ncount of them) numbers into out. Returns the
 * count read, 0 if unset (out untouched), -1 on error. */
static int read_numbers(const mjModel* m, int instance, const char* who, const char* key,
                        double* out, const int* counts, int ncount, const char* expect,
                        err_t* e) {
  const char* v = config(m, instance, key);
  if (!v) return 0;
  char sb[200];
  double tmp[36];
  int bad = 0;
  int n = parse_numbers(v, strlen(v), tmp, 36, &bad);
  if (n == -1) {
    fail(e, "%s: %s = \"%s\": number %d is not a number; expected %s", who, key,
         shown(v, sb, sizeof(sb)), bad + 1, expect);
    return -1;
  }
  if (n == -2) {
    fail(e, "%s: %s = \"%s\": number %d is not finite (NaN or inf); expected %s", who, key,
         shown(v, sb, sizeof(sb)), bad + 1, expect);
    return -1;
  }
  for (int i = 0; i < ncount; i++)
    if (n == counts[i]) {
      memcpy(out, tmp, sizeof(double) * n);
      return n;
    }
  fail(e, "%s: %s = \"%s\": got %d numbers; expected %s", who, key, shown(v, sb, sizeof(sb)), n,
       expect);
  return -1;
}

static void check_all(const char* who, const char* key, const char* v, const double* x, int n,
                      int strict, const char* what, err_t* e) {
  char sb[200];
  for (int i = 0; i < n; i++) {
    if (strict ? !(x[i] > 0) : !(x[i] >= 0)) {
      fail(e, "%s: %s = \"%s\": number %d (%g) must be %s", who, key, shown(v, sb, sizeof(sb)),
           i + 1, x[i], what);
      return;
    }
  }
}

/* Split a ';'-separated list; calls back with each non-blank segment. */
typedef int (*segment_fn)(void* ctx, int index, const char* s, size_t len);
static int split_segments(const char* v, segment_fn fn, void* ctx) {
  int index = 0;
  const char* p = v;
  while (1) {
    const char* q = strchr(p, ';');
    size_t len = q ? (size_t)(q - p) : strlen(p);
    int blank = 1;
    for (size_t i = 0; i < len; i++)
      if (!is_space(p[i])) blank = 0;
    if (!blank) {
      if (fn(ctx, index, p, len)) return -1;
      index++;
    }
    if (!q) break;
    p = q + 1;
  }
  return index;
}

/* ---- strips */

typedef struct {
  const char* who;
  const char* value;
  err_t* e;
  strip_t* out;   /* NULL: count only */
} strip_ctx;

static int strip_segment(void* vctx, int index, const char* s, size_t len) {
  strip_ctx* c = (strip_ctx*)vctx;
  char sb[200];
  const char* v = shown(c->value, sb, sizeof(sb));
  size_t i = 0;
  while (i < len && is_space(s[i])) i++;
  size_t j = i;
  while (j < len && !is_space(s[j])) j++;
  int axis = -1;
  if (j - i == 1 && (s[i] == 'x' || s[i] == 'y' || s[i] == 'z')) axis = s[i] - 'x';
  if (axis < 0) {
    fail(c->e, "%s: strips = \"%s\": strip %d: axis '%.*s' unknown; expected 'axis s0 s1 cd1 cd2' "
         "with axis x, y or z", c->who, v, index + 1, (int)(j - i), s + i);
    return -1;
  }
  double x[4];
  int bad = 0;
  int n = parse_numbers(s + j, len - j, x, 4, &bad);
  if (n < 0) {
    fail(c->e, "%s: strips = \"%s\": strip %d: number %d is %s; expected 'axis s0 s1 cd1 cd2'",
         c->who, v, index + 1, bad + 1, n == -1 ? "not a number" : "not finite");
    return -1;
  }
  if (n != 4) {
    fail(c->e, "%s: strips = \"%s\": strip %d has %d numbers after the axis; expected 4 "
         "('axis s0 s1 cd1 cd2', strips separated by ';')", c->who, v, index + 1, n);
    return -1;
  }
  if (!(x[0] < x[1])) {
    fail(c->e, "%s: strips = \"%s\": strip %d: s0 (%g) must be < s1 (%g)", c->who, v, index + 1,
         x[0], x[1]);
    return -1;
  }
  if (!(x[2] >= 0 && x[3] >= 0)) {
    fail(c->e, "%s: strips = \"%s\": strip %d: cd1 (%g) and cd2 (%g) must be >= 0", c->who, v,
         index + 1, x[2], x[3]);
    return -1;
  }
  if (c->out) {
    c->out[index].axis = axis;
    c->out[index].s0 = x[0];
    c->out[index].s1 = x[1];
    c->out[index].cd[0] = x[2];
    c->out[index].cd[1] = x[3];
  }
  return 0;
}

/* ---- profile */

typedef struct {
  const char* value;
  err_t* e;
  double* out;
} knot_ctx;

static int knot_segment(void* vctx, int index, const char* s, size_t len) {
  knot_ctx* c = (knot_ctx*)vctx;
  char sb[200];
  const char* v = shown(c->value, sb, sizeof(sb));
  double x[4];
  int bad = 0;
  int n = parse_numbers(s, len, x, 4, &bad);
  if (n < 0) {
    fail(c->e, "uvms.water: profile = \"%s\": knot %d: number %d is %s; expected 'z vx vy vz' "
         "knots separated by ';'", v, index + 1, bad + 1, n == -1 ? "not a number" : "not finite");
    return -1;
  }
  if (n != 4) {
    fail(c->e, "uvms.water: profile = \"%s\": knot %d has %d numbers; expected 4 ('z vx vy vz', "
         "knots separated by ';')", v, index + 1, n);
    return -1;
  }
  if (c->out) {
    if (index > 0 && !(x[0] > c->out[4 * (index - 1)])) {
      fail(c->e, "uvms.water: profile = \"%s\": knot %d: z = %g must be greater than the previous "
           "knot's z = %g (z strictly increasing)", v, index + 1, x[0], c->out[4 * (index - 1)]);
      return -1;
    }
    memcpy(c->out + 4 * index, x, sizeof(x));
  }
  return 0;
}

/* ------------------------------------------------------------------ init helpers */

static int find_slot(const char* name) {
  int slot = -1;
  if (!mjp_getPlugin(name, &slot)) return -1;
  return slot;
}

static void body_label(const mjModel* m, int b, char* buf, size_t n) {
  const char* name = mj_id2name(m, mjOBJ_BODY, b);
  if (name && *name)
    snprintf(buf, n, "body '%s'", name);
  else
    snprintf(buf, n, "body %d (unnamed)", b);
}

static void free_water(water_t* w) {
  if (!w) return;
  if (w->bodies) {
    for (int i = 0; i < w->nbody; i++) {
      free(w->bodies[i].strips);
      free(w->bodies[i].chain);
    }
    free(w->bodies);
  }
  free(w->knots);
  uvms_waves_free(&w->waves);
  free(w->Mcopy);
  free(w->active);
  free(w->fdof);
  free(w->dof_quat);
  free(w->Fb);
  free(w->Bb);
  free(w->J);
  free(w->W);
  free(w);
}

/* an integer seed attribute (unset: *out untouched) */
static void parse_seed(const mjModel* m, int inst, const char* who, const char* key, uint64_t* out,
                       err_t* e) {
  char sb[200];
  const char* sv = config(m, inst, key);
  if (sv) {
    const char* p = sv;
    while (is_space(*p)) p++;
    const char* q = p;
    while (*q >= '0' && *q <= '9') q++;
    const char* r = q;
    while (is_space(*r)) r++;
    char* end = NULL;
    unsigned long long s = 0;
    int ok = q > p && !*r;
    if (ok) {
      errno = 0;
      s = strtoull(p, &end, 10);
      ok = end == q && errno == 0;
    }
    if (!ok)
      fail(e, "%s: %s = \"%s\": expected 1 integer >= 0 (at most 18446744073709551615)", who, key,
           shown(sv, sb, sizeof(sb)));
    else
      *out = (uint64_t)s;
  }
}

/* the wave attributes (docs/hydrodynamics.md "Waves") */
static void parse_waves(const mjModel* m, int inst, water_t* w, err_t* e) {
  const char* who = "uvms.water";
  char sb[200];
  int c1[] = {1};
  waves_params_t* p = &w->wave;
  memset(p, 0, sizeof(*p));
  p->model = WAVES_NONE;
  p->gamma = 3.3;
  p->ncomp = WAVES_DEFAULT_COMPONENTS;
  const char* mv = config(m, inst, "wave_model");
  if (mv) {
    char word[64], rest[8];
    if (sscanf(mv, " %63s", word) != 1) word[0] = 0;
    int extra = sscanf(mv, " %*63s %7s", rest) == 1;
    if (!extra && !strcmp(word, "none"))
      p->model = WAVES_NONE;
    else if (!extra && !strcmp(word, "airy"))
      p->model = WAVES_AIRY;
    else if (!extra && !strcmp(word, "jonswap"))
      p->model = WAVES_JONSWAP;
    else if (!extra && !strcmp(word, "pierson_moskowitz"))
      p->model = WAVES_PM;
    else
      fail(e, "%s: wave_model = \"%s\": unknown; allowed: none, airy, jonswap, pierson_moskowitz", who,
           shown(mv, sb, sizeof(sb)));
  }
  double x = 0.0;
  if (read_numbers(m, inst, who, "wave_height", &p->height, c1, 1, "1 number (m, > 0)", e) > 0)
    check_all(who, "wave_height", config(m, inst, "wave_height"), &p->height, 1, 1, "> 0", e);
  if (read_numbers(m, inst, who, "wave_period", &p->period, c1, 1, "1 number (s, > 0)", e) > 0)
    check_all(who, "wave_period", config(m, inst, "wave_period"), &p->period, 1, 1, "> 0", e);
  if (read_numbers(m, inst, who, "wave_gamma", &p->gamma, c1, 1, "1 number (1 <= gamma <= 7)", e) > 0 &&
      !(p->gamma >= 1.0 && p->gamma <= 7.0))
    fail(e, "%s: wave_gamma = %g: must be in [1, 7] (DNV-RP-C205 3.5.5)", who, p->gamma);
  read_numbers(m, inst, who, "wave_direction", &p->direction, c1, 1, "1 number (rad, world)", e);
  if (read_numbers(m, inst, who, "wave_spreading", &p->spreading, c1, 1, "1 number (>= 0)", e) > 0 &&
      !(p->spreading >= 0.0 && p->spreading <= WAVES_MAX_SPREADING))
    fail(e, "%s: wave_spreading = %g: must be in [0, %g] (cos^n exponent n; 0: long-crested)", who,
         p->spreading, WAVES_MAX_SPREADING);
  if (read_numbers(m, inst, who, "wave_depth", &p->depth, c1, 1, "1 number (m, > 0; 0: deep water)", e) > 0)
    check_all(who, "wave_depth", config(m, inst, "wave_depth"), &p->depth, 1, 0, ">= 0 (0: deep water)", e);
  read_numbers(m, inst, who, "surface", &p->surface, c1, 1, "1 number (m, world z)", e);
  parse_seed(m, inst, who, "wave_seed", &p->seed, e);
  if (read_numbers(m, inst, who, "wave_components", &x, c1, 1, "1 integer in [1, 10000]", e) > 0) {
    if (!(x >= 1 && x <= WAVES_MAX_COMPONENTS && x == floor(x)))
      fail(e, "%s: wave_components = %g: expected 1 integer in [1, %d]", who, x, WAVES_MAX_COMPONENTS);
    else
      p->ncomp = (int)x;
  }
  if (p->model != WAVES_NONE && !e->failed) {
    if (!(p->height > 0.0))
      fail(e, "%s: wave_model = %s needs wave_height (m, > 0: H for airy, Hs for a spectrum)", who,
           mv);
    else if (!(p->period > 0.0))
      fail(e, "%s: wave_model = %s needs wave_period (s, > 0: T for airy, Tp for a spectrum)", who,
           mv);
  }
}

static void parse_water(const mjModel* m, int inst, water_t* w, err_t* e) {
  const char* who = "uvms.water";
  char sb[200];
  int c1[] = {1}, c3[] = {3};
  w->rho = 1000.0;
  if (read_numbers(m, inst, who, "density", &w->rho, c1, 1, "1 number (kg/m^3, > 0)", e) > 0)
    check_all(who, "density", config(m, inst, "density"), &w->rho, 1, 1, "> 0", e);
  read_numbers(m, inst, who, "current", w->current, c3, 1, "3 numbers (m/s, world)", e);

  const char* cm = config(m, inst, "current_model");
  w->model = CURRENT_CONSTANT;
  if (cm) {
    char word[64];
    if (sscanf(cm, " %63s", word) != 1) word[0] = 0;
    char rest[8];
    int extra = sscanf(cm, " %*63s %7s", rest) == 1;
    if (!extra && !strcmp(word, "constant"))
      w->model = CURRENT_CONSTANT;
    else if (!extra && !strcmp(word, "gauss_markov"))
      w->model = CURRENT_GAUSS_MARKOV;
    else if (!extra && !strcmp(word, "profile"))
      w->model = CURRENT_PROFILE;
    else
      fail(e, "%s: current_model = \"%s\": unknown; allowed: constant, gauss_markov, profile", who,
           shown(cm, sb, sizeof(sb)));
  }

  memcpy(w->mean, w->current, sizeof(w->mean));
  for (int c = 0; c < 3; c++) {
    w->sigma[c] = 0.0;
    w->tau[c] = 10.0;
    w->vmin[c] = -1e3;
    w->vmax[c] = 1e3;
  }
  read_numbers(m, inst, who, "gm_mean", w->mean, c3, 1, "3 numbers (m/s, world)", e);
  if (read_numbers(m, inst, who, "gm_sigma", w->sigma, c3, 1, "3 numbers (m/s, >= 0)", e) > 0)
    check_all(who, "gm_sigma", config(m, inst, "gm_sigma"), w->sigma, 3, 0, ">= 0", e);
  if (read_numbers(m, inst, who, "gm_tau", w->tau, c3, 1, "3 numbers (s, > 0)", e) > 0)
    check_all(who, "gm_tau", config(m, inst, "gm_tau"), w->tau, 3, 1, "> 0", e);
  read_numbers(m, inst, who, "gm_min", w->vmin, c3, 1, "3 numbers (m/s)", e);
  read_numbers(m, inst, who, "gm_max", w->vmax, c3, 1, "3 numbers (m/s)", e);
  for (int c = 0; c < 3 && !e->failed; c++) {
    if (!(w->vmin[c] <= w->vmax[c]))
      fail(e, "%s: gm_min (%g) > gm_max (%g) in component %d; need gm_min <= gm_max", who,
           w->vmin[c], w->vmax[c], c + 1);
  }

  w->seed = 0;
  parse_seed(m, inst, who, "gm_seed", &w->seed, e);

  const char* pv = config(m, inst, "profile");
  if (pv && !e->failed) {
    knot_ctx kc = {pv, e, NULL};
    int n = split_segments(pv, knot_segment, &kc);
    if (n > 0) {
      w->knots = (double*)calloc(4 * (size_t)n, sizeof(double));
      if (!w->knots) {
        fail(e, "%s: out of memory", who);
        return;
      }
      kc.out = w->knots;
      if (split_segments(pv, knot_segment, &kc) == n) w->nknot = n;
    }
  }
  if (w->model == CURRENT_PROFILE && !e->failed && w->nknot == 0)
    fail(e, "%s: current_model = \"profile\" needs a profile: 'z vx vy vz' knots separated by ';'",
         who);

  parse_waves(m, inst, w, e);

  w->terms = TERM_ALL;
  const char* tv = config(m, inst, "terms");
  char first[16] = "", second[2] = "";
  if (tv && sscanf(tv, " %15s %1s", first, second) == 1 && !strcmp(first, "none")) {
    w->terms = 0; /* "none" alone: every term off (an empty value is unset: all on) */
  } else if (tv) {
    w->terms = 0;
    const char* p = tv;
    while (*p && !e->failed) {
      while (*p && is_space(*p)) p++;
      if (!*p) break;
      const char* q = p;
      while (*q && !is_space(*q)) q++;
      int found = -1;
      for (int t = 0; t < 5; t++)
        if ((size_t)(q - p) == strlen(term_words[t]) && !strncmp(p, term_words[t], q - p))
          found = t;
      if (found < 0)
        fail(e, "%s: terms = \"%s\": unknown term '%.*s'; allowed: added_mass damping strips "
             "buoyancy froude_krylov, or none alone", who, shown(tv, sb, sizeof(sb)),
             (int)(q - p), p);
      else
        w->terms |= 1 << found;
      p = q;
    }
  }
}

static void parse_body(const mjModel* m, int inst, int b, hbody_t* hb, err_t* e) {
  char who[300], label[256], sb[200];
  body_label(m, b, label, sizeof(label));
  snprintf(who, sizeof(who), "uvms.hydro: %s", label);
  int c1[] = {1}, c3[] = {3}, c4[] = {4}, c6[] = {6}, cam[] = {6, 21, 36};
  hb->body = b;

  memcpy(hb->pos, m->body_ipos + 3 * b, sizeof(hb->pos));
  read_numbers(m, inst, who, "pos", hb->pos, c3, 1, "3 numbers (m, body frame)", e);

  hb->quat[0] = 1;
  hb->quat[1] = hb->quat[2] = hb->quat[3] = 0;
  if (read_numbers(m, inst, who, "quat", hb->quat, c4, 1, "4 numbers (w x y z)", e) > 0) {
    double nrm = sqrt(hb->quat[0] * hb->quat[0] + hb->quat[1] * hb->quat[1] +
                      hb->quat[2] * hb->quat[2] + hb->quat[3] * hb->quat[3]);
    if (!(nrm > 1e-10))
      fail(e, "%s: quat = \"%s\": must not be zero (a rotation w x y z, normalised here)", who,
           shown(config(m, inst, "quat"), sb, sizeof(sb)));
    else
      for (int i = 0; i < 4; i++) hb->quat[i] /= nrm;
  }
  mju_quat2Mat(hb->hmat, hb->quat);
  hb->hident = hb->quat[0] == 1.0 && hb->quat[1] == 0.0 && hb->quat[2] == 0.0 &&
               hb->quat[3] == 0.0;

  double am[36] = {0};
  int n = read_numbers(m, inst, who, "added_mass", am, cam, 3,
                       "6, 21 or 36 numbers (diagonal, upper triangle row by row, or full 6x6)", e);
  memset(hb->MA, 0, sizeof(hb->MA));
  if (n == 6) {
    for (int i = 0; i < 6; i++) hb->MA[7 * i] = am[i];
  } else if (n == 21) {
    int k = 0;
    for (int i = 0; i < 6; i++)
      for (int j = i; j < 6; j++) {
        hb->MA[6 * i + j] = am[k];
        hb->MA[6 * j + i] = am[k];
        k++;
      }
  } else if (n == 36) {
    memcpy(hb->MA, am, sizeof(hb->MA));
  }
  if (n > 0 && !e->failed) {
    const char* v = shown(config(m, inst, "added_mass"), sb, sizeof(sb));
    double mx = 0.0;
    for (int i = 0; i < 36; i++)
      if (fabs(hb->MA[i]) > mx) mx = fabs(hb->MA[i]);
    for (int i = 0; i < 6 && !e->failed; i++)
      for (int j = 0; j < i && !e->failed; j++)
        if (fabs(hb->MA[6 * i + j] - hb->MA[6 * j + i]) > 1e-12 * mx)
          fail(e, "%s: added_mass = \"%s\": not symmetric (entry (%d,%d) = %g, (%d,%d) = %g); "
               "M_A must be symmetric positive semi-definite", who, v, i + 1, j + 1,
               hb->MA[6 * i + j], j + 1, i + 1, hb->MA[6 * j + i]);
    if (!e->failed && mx > 0) {
      double ev = min_eig6(hb->MA);
      if (ev < -1e-12 * mx)
        fail(e, "%s: added_mass = \"%s\": not positive semi-definite (smallest eigenvalue %g); "
             "coefficients are positive (M_A = -[X_udot ...]) and M_A must be symmetric positive "
             "semi-definite", who, v, ev);
    }
  }
  hb->has_am = 0;
  hb->diag_am = 1;
  for (int i = 0; i < 36; i++) {
    if (hb->MA[i] != 0.0) {
      hb->has_am = 1;
      if (i % 7) hb->diag_am = 0;
    }
  }

  if (read_numbers(m, inst, who, "linear_damping", hb->DL, c6, 1, "6 numbers (>= 0)", e) > 0)
    check_all(who, "linear_damping", config(m, inst, "linear_damping"), hb->DL, 6, 0, ">= 0", e);
  if (read_numbers(m, inst, who, "quadratic_damping", hb->DQ, c6, 1, "6 numbers (>= 0)", e) > 0)
    check_all(who, "quadratic_damping", config(m, inst, "quadratic_damping"), hb->DQ, 6, 0,
              ">= 0", e);
  hb->has_damp = 0;
  for (int i = 0; i < 6; i++)
    if (hb->DL[i] != 0.0 || hb->DQ[i] != 0.0) hb->has_damp = 1;

  if (read_numbers(m, inst, who, "volume", &hb->volume, c1, 1, "1 number (m^3, >= 0)", e) > 0)
    check_all(who, "volume", config(m, inst, "volume"), &hb->volume, 1, 0, ">= 0", e);

  memcpy(hb->cob, hb->pos, sizeof(hb->cob));
  read_numbers(m, inst, who, "cob", hb->cob, c3, 1, "3 numbers (m, body frame)", e);

  const char* sv = config(m, inst, "strips");
  if (sv && !e->failed) {
    strip_ctx sc = {who, sv, e, NULL};
    int ns = split_segments(sv, strip_segment, &sc);
    if (ns > 0) {
      hb->strips = (strip_t*)calloc((size_t)ns, sizeof(strip_t));
      if (!hb->strips) {
        fail(e, "%s: out of memory", who);
        return;
      }
      sc.out = hb->strips;
      if (split_segments(sv, strip_segment, &sc) == ns) hb->nstrip = ns;
    }
  }
  if (e->failed) return;

  /* dof chain: the dofs of the nearest ancestor (or self) with dofs, and all their ancestors */
  int b0 = b;
  while (b0 > 0 && m->body_dofnum[b0] == 0) b0 = m->body_parentid[b0];
  int nc = 0;
  if (b0 > 0)
    for (int j = m->body_dofadr[b0] + m->body_dofnum[b0] - 1; j >= 0; j = m->dof_parentid[j])
      nc++;
  hb->nc = nc;
  if (nc) {
    hb->chain = (int*)malloc(sizeof(int) * nc);
    if (!hb->chain) {
      fail(e, "%s: out of memory", who);
      return;
    }
    int k = nc;
    for (int j = m->body_dofadr[b0] + m->body_dofnum[b0] - 1; j >= 0; j = m->dof_parentid[j])
      hb->chain[--k] = j;
    /* row chain[a] of the CSR lower triangle of M must hold exactly chain[0..a] (it does for
     * every non-simple body: all pairs of ancestor dofs); compute walks it backwards */
    int missing = 0;
    for (int a = 0; a < nc; a++) {
      int row = hb->chain[a];
      if (m->M_rownnz[row] != a + 1) {
        missing = 1;
        continue;
      }
      for (int c = 0; c <= a; c++)
        if (m->M_colind[m->M_rowadr[row] + c] != hb->chain[c]) missing = 1;
    }
    if (hb->has_am && (missing || m->body_simple[b0] || m->body_simple[b])) {
      fail(e, "%s: added_mass on a \"simple\" body (a childless body on a free joint, whose mass "
           "matrix MuJoCo keeps diagonal): its off-diagonal added mass would be silently dropped; "
           "weld a child body to it (e.g. <body><geom type=\"sphere\" size=\"0.01\" "
           "mass=\"0.001\"/></body>) or give it <inertial> and a child body", who);
      return;
    }
  }
}

/* ------------------------------------------------------------------ uvms.water callbacks */

static int water_nstate(const mjModel* m, int instance) { return WATER_NSTATE; }

static void water_reset(const mjModel* m, mjtNum* s, void* plugin_data, int instance) {
  water_t* w = (water_t*)plugin_data;
  if (!w) return;
  w->Mvalid = 0;
  double h = m->opt.timestep;
  s[0] = 0.0;
  s[1] = 0.0;
  for (int c = 0; c < 3; c++) s[2 + c] = s[5 + c] = w->current[c];
  s[8] = h;
  if (w->model == CURRENT_GAUSS_MARKOV) gm_draw(w, s + 2, 0, h, s + 5);
}

static void water_advance(const mjModel* m, mjData* d, int instance) {
  water_t* w = (water_t*)d->plugin_data[instance];
  if (!w || w->model != CURRENT_GAUSS_MARKOV) return;
  mjtNum* s = d->plugin_state + m->plugin_stateadr[instance];
  double h = m->opt.timestep;
  s[0] = d->time;
  s[1] += 1.0;
  for (int c = 0; c < 3; c++) s[2 + c] = s[5 + c];
  s[8] = h;
  gm_draw(w, s + 2, (uint64_t)s[1], h, s + 5);
}

static int water_init(const mjModel* m, mjData* d, int instance) {
  err_t e = {{0}, 0};
  int hslot = find_slot("uvms.hydro");
  int wslot = m->plugin[instance];
  for (int i = 0; i < m->nplugin; i++)
    if (i != instance && m->plugin[i] == wslot) {
      mju_error("uvms.water: the model has more than one uvms.water instance; declare exactly one "
                "(<extension><plugin plugin=\"uvms.water\"><instance name=\"water\">...)");
      return -1;
    }
  for (int b = 0; b < m->nbody; b++)
    if (m->body_plugin[b] == instance) {
      char label[256];
      body_label(m, b, label, sizeof(label));
      mju_error("uvms.water: attached to %s; uvms.water is a model-level instance under "
                "<extension> (bodies take uvms.hydro)", label);
      return -1;
    }

  water_t* w = (water_t*)calloc(1, sizeof(water_t));
  if (!w) {
    mju_error("uvms.water: out of memory");
    return -1;
  }
  w->instance = instance;
  parse_water(m, instance, w, &e);
  if (!e.failed && w->wave.model != WAVES_NONE) {
    const double* gv = m->opt.gravity;
    char werr[200];
    if (!(gv[0] == 0.0 && gv[1] == 0.0 && gv[2] < 0.0))
      fail(&e, "uvms.water: waves need gravity along -z (opt.gravity = 0 0 -g, g > 0; got %g %g %g): "
           "the mean surface is a plane z = surface", gv[0], gv[1], gv[2]);
    else if (uvms_waves_build(&w->wave, -gv[2], &w->waves, werr, sizeof(werr)))
      fail(&e, "uvms.water: waves: %s", werr);
  }

  int nb = 0;
  for (int b = 1; b < m->nbody; b++)
    if (m->body_plugin[b] >= 0 && hslot >= 0 && m->plugin[m->body_plugin[b]] == hslot) nb++;
  if (nb && !e.failed) {
    w->bodies = (hbody_t*)calloc((size_t)nb, sizeof(hbody_t));
    if (!w->bodies) fail(&e, "uvms.water: out of memory");
  }
  for (int b = 1; b < m->nbody && !e.failed; b++) {
    int pi = m->body_plugin[b];
    if (pi < 0 || hslot < 0 || m->plugin[pi] != hslot) continue;
    parse_body(m, pi, b, &w->bodies[w->nbody], &e);
    w->nbody++;
  }

  if (!e.failed) {
    w->nv = m->nv;
    w->nC = m->nC;
    for (int i = 0; i < w->nbody; i++) {
      if (w->bodies[i].has_am) w->any_am = 1;
    }
    /* active bodies (with uvms.hydro, and their ancestors) and force dofs */
    unsigned char* mark = (unsigned char*)calloc((size_t)m->nbody + (size_t)m->nv + 1, 1);
    w->active = (int*)malloc(sizeof(int) * (size_t)(m->nbody + 1));
    w->fdof = (int*)malloc(sizeof(int) * (size_t)(m->nv + 1));
    w->dof_quat = (unsigned char*)calloc((size_t)m->nv + 1, 1);
    w->Mcopy = (double*)calloc((size_t)(m->nC > 0 ? m->nC : 1), sizeof(double));
    w->Fb = (double*)calloc(6 * (size_t)m->nbody, sizeof(double));
    w->Bb = (double*)calloc(6 * (size_t)m->nbody, sizeof(double));
    for (int i = 0; i < w->nbody; i++)
      if (w->bodies[i].nc > w->maxnc) w->maxnc = w->bodies[i].nc;
    w->J = (double*)calloc(6 * (size_t)w->maxnc + 6, sizeof(double));
    w->W = (double*)calloc(6 * (size_t)w->maxnc + 6, sizeof(double));
    if (!mark || !w->active || !w->fdof || !w->dof_quat || !w->Mcopy || !w->Fb || !w->Bb ||
        !w->J || !w->W) {
      fail(&e, "uvms.water: out of memory");
    } else {
      unsigned char* fmark = mark + m->nbody;
      for (int i = 0; i < w->nbody; i++) {
        const hbody_t* hb = w->bodies + i;
        if (!hb->nc) continue;
        for (int k = hb->body; k > 0; k = m->body_parentid[k]) mark[k] = 1;
        for (int a = 0; a < hb->nc; a++) fmark[hb->chain[a]] = 1;
      }
      for (int k = 1; k < m->nbody; k++)
        if (mark[k]) w->active[w->nactive++] = k;
      for (int j = 0; j < m->nv; j++) {
        if (fmark[j]) w->fdof[w->nfdof++] = j;
        int jnt = m->dof_jntid[j], type = m->jnt_type[jnt];
        w->dof_quat[j] = type == mjJNT_BALL || (type == mjJNT_FREE && j >= m->jnt_dofadr[jnt] + 3);
      }
    }
    free(mark);
  }
  if (e.failed) {
    free_water(w);
    mju_error("%s", e.msg);
    return -1;
  }
  d->plugin_data[instance] = (uintptr_t)w;
  return 0;
}

static void water_destroy(mjData* d, int instance) {
  free_water((water_t*)d->plugin_data[instance]);
  d->plugin_data[instance] = 0;
}

static void water_copy(mjData* dest, const mjModel* m, const mjData* src, int instance) {
  water_t* wd = (water_t*)dest->plugin_data[instance];
  const water_t* ws = (const water_t*)src->plugin_data[instance];
  if (!wd || !ws || wd == ws) return;
  /* same model: parameters, chains and sizes are equal; copy the guard */
  if (wd->nC == ws->nC) memcpy(wd->Mcopy, ws->Mcopy, sizeof(double) * (size_t)ws->nC);
  wd->Mvalid = ws->Mvalid;
}

/* current (world) at the point p and time t, and its acceleration */
static void current_at(const water_t* w, const mjtNum* s, double t, const double p[3],
                       double vc[3], double ac[3]) {
  ac[0] = ac[1] = ac[2] = 0.0;
  if (w->model == CURRENT_PROFILE) {
    const double* k = w->knots;
    int n = w->nknot;
    double z = p[2];
    if (z <= k[0]) {
      memcpy(vc, k + 1, 3 * sizeof(double));
    } else if (z >= k[4 * (n - 1)]) {
      memcpy(vc, k + 4 * (n - 1) + 1, 3 * sizeof(double));
    } else {
      int i = 0;
      while (i + 1 < n - 1 && z >= k[4 * (i + 1)]) i++;
      double f = (z - k[4 * i]) / (k[4 * (i + 1)] - k[4 * i]);
      for (int c = 0; c < 3; c++)
        vc[c] = k[4 * i + 1 + c] + f * (k[4 * (i + 1) + 1 + c] - k[4 * i + 1 + c]);
    }
    return;
  }
  if (w->model == CURRENT_CONSTANT) {
    vc[0] = s[2];
    vc[1] = s[3];
    vc[2] = s[4];
    return;
  }
  double h = s[8];
  double f = 0.0;
  if (h > 0) {
    f = (t - s[0]) / h;
    if (!(f > 0.0)) f = 0.0;
    if (f > 1.0) f = 1.0;
  }
  for (int c = 0; c < 3; c++) {
    double dv = s[5 + c] - s[2 + c];
    vc[c] = s[2 + c] + f * dv;
    ac[c] = h > 0 ? dv / h : 0.0;
  }
}

/* cdof_dot of dof j as mj_jacDot uses it (ball and free-rotation dofs: cvel(body) x cdof) */
static inline const double* cdof_dot(const mjModel* m, const mjData* d, int j, int quat,
                                     double tmp[6]) {
  if (!quat) return d->cdof_dot + 6 * j;
  const double* bv = d->cvel + 6 * m->dof_bodyid[j];
  const double* cd = d->cdof + 6 * j;
  double t1[3];
  cross3(tmp, bv, cd);         /* ang: w x ang */
  cross3(tmp + 3, bv, cd + 3); /* lin: w x lin + v x ang */
  cross3(t1, bv + 3, cd);
  tmp[3] += t1[0];
  tmp[4] += t1[1];
  tmp[5] += t1[2];
  return tmp;
}

static void water_compute(const mjModel* m, mjData* d, int instance, int capability_bit) {
  water_t* w = (water_t*)d->plugin_data[instance];
  if (!w || !w->nbody || !w->nactive) return;
  const int terms = w->terms;
  const mjtNum* s = d->plugin_state + m->plugin_stateadr[instance];
  const double rho = w->rho;
  double g[3] = {m->opt.gravity[0], m->opt.gravity[1], m->opt.gravity[2]};
  if (m->opt.disableflags & mjDSBL_GRAVITY) g[0] = g[1] = g[2] = 0.0;
  const int am_on = (terms & TERM_ADDED_MASS) && w->any_am;

  /* guard: add the added mass only if d->M is not the one augmented last */
  const int add_mass = am_on && !(w->Mvalid && !memcmp(d->M, w->Mcopy, sizeof(mjtNum) * (size_t)m->nC));

  double* Fb = w->Fb;      /* per body: spatial force (torque about com, force), subtree sum */
  double* Bb = w->Bb;      /* per body: sum over its chain of qvel cdof_dot (bias) */
  const int* active = w->active;
  const int nactive = w->nactive;

  /* forward pass (parents first): clear, and the bias sums when the added mass is on */
  for (int ia = 0; ia < nactive; ia++) {
    const int k = active[ia];
    memset(Fb + 6 * k, 0, 6 * sizeof(double));
    if (am_on) {
      double* B = Bb + 6 * k;
      const int par = m->body_parentid[k];
      if (par > 0)
        memcpy(B, Bb + 6 * par, 6 * sizeof(double));
      else
        memset(B, 0, 6 * sizeof(double));
      const int j0 = m->body_dofadr[k], nd = m->body_dofnum[k];
      for (int j = j0; j < j0 + nd; j++) {
        double tmp[6];
        const double* cdd = cdof_dot(m, d, j, w->dof_quat[j], tmp);
        const double q = d->qvel[j];
        for (int c = 0; c < 6; c++) B[c] += cdd[c] * q;
      }
    }
  }

  for (int ib = 0; ib < w->nbody; ib++) {
    const hbody_t* hb = w->bodies + ib;
    const int b = hb->body;
    const double* xmat = d->xmat + 9 * b;
    const double* xpos = d->xpos + 3 * b;
    const int use_am = am_on && hb->has_am;
    const int use_damp = (terms & TERM_DAMPING) && hb->has_damp;
    const int use_strip = (terms & TERM_STRIPS) && hb->nstrip;
    const int use_buoy = (terms & TERM_BUOYANCY) && hb->volume != 0.0;
    const int use_fk = (terms & TERM_FROUDE_KRYLOV) && hb->volume != 0.0 &&
                       (w->model == CURRENT_GAUSS_MARKOV || w->waves.n);
    if (!hb->nc || !(use_am || use_damp || use_strip || use_buoy || use_fk)) continue;

    /* frame h: R = xmat * hmat, p = xpos + xmat pos */
    double R[9], p[3];
    if (hb->hident) {
      memcpy(R, xmat, sizeof(R));
    } else {
      const double* H = hb->hmat; /* R = xmat H (3x3, row-major), inline: mju_mulMatMat's
                                     generic loop costs ~10x more here */
      for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++)
          R[3 * r + c] = xmat[3 * r] * H[c] + xmat[3 * r + 1] * H[3 + c] + xmat[3 * r + 2] * H[6 + c];
    }
    mul3(p, xmat, hb->pos);
    p[0] += xpos[0];
    p[1] += xpos[1];
    p[2] += xpos[2];

    /* nu = J qvel from the body's cvel (motion at the subtree centre of mass of the root, world
     * axes; the sum of cdof qvel along the chain), moved to p, in frame h */
    const double* com = d->subtree_com + 3 * m->body_rootid[b];
    const double* cv = d->cvel + 6 * b;
    double off[3] = {p[0] - com[0], p[1] - com[1], p[2] - com[2]};
    double vp[3]; /* world velocity of p */
    cross3(vp, cv, off);
    vp[0] += cv[3];
    vp[1] += cv[4];
    vp[2] += cv[5];
    double nu[6];
    mulT3(nu, R, vp);
    mulT3(nu + 3, R, cv);

    double vc[3], ac[3], vch[3], ach[3];
    current_at(w, s, d->time, p, vc, ac);
    double vwp[3] = {0, 0, 0}; /* the waves at p (world) */
    if (w->waves.n) {
      /* v_c += v_w; a_c += dv_w/dt + grad(v_w) (v_c + v_w): the material acceleration of the water */
      double awp[3], gw[9];
      uvms_waves_kinematics(&w->waves, d->time, p, vwp, awp, gw);
      for (int c = 0; c < 3; c++) vc[c] += vwp[c];
      for (int c = 0; c < 3; c++)
        ac[c] += awp[c] + gw[3 * c] * vc[0] + gw[3 * c + 1] * vc[1] + gw[3 * c + 2] * vc[2];
    }
    mulT3(vch, R, vc);
    double nur[6] = {nu[0] - vch[0], nu[1] - vch[1], nu[2] - vch[2], nu[3], nu[4], nu[5]};
    const double* vr = nur;
    const double* wv = nur + 3;
    double tau[6] = {0, 0, 0, 0, 0, 0};

    if (use_am) {
      const double* A = hb->MA;
      double hm[6], acc[6], tmp[3];
      if (hb->diag_am) {
        for (int i = 0; i < 6; i++) hm[i] = A[7 * i] * nur[i];
      } else {
        for (int i = 0; i < 6; i++) {
          double sum = 0.0;
          for (int k = 0; k < 6; k++) sum += A[6 * i + k] * nur[k];
          hm[i] = sum;
        }
      }
      /* Kirchhoff: [h_v x w ; h_v x v_r + h_w x w] */
      cross3(tmp, hm, wv);
      tau[0] += tmp[0];
      tau[1] += tmp[1];
      tau[2] += tmp[2];
      cross3(tmp, hm, vr);
      tau[3] += tmp[0];
      tau[4] += tmp[1];
      tau[5] += tmp[2];
      cross3(tmp, hm + 3, wv);
      tau[3] += tmp[0];
      tau[4] += tmp[1];
      tau[5] += tmp[2];
      /* (Jp_dot qd, Jr_dot qd) as mj_jacDot computes them, without the matrices: with the
       * chain sum Bs = sum_j qvel_j cdof_dot_j, Jr_dot qd = Bs_ang and
       * Jp_dot qd = Bs_lin + Bs_ang x (p - com) + omega x v_p. Then
       * a = [R^T Jp_dot qd - w x v_r ; R^T Jr_dot qd], and -M_A (a - [R^T a_c; 0]). */
      const double* Bs = Bb + 6 * b;
      double lp[3], t2[3];
      cross3(lp, Bs, off);
      cross3(t2, cv, vp);
      lp[0] += Bs[3] + t2[0];
      lp[1] += Bs[4] + t2[1];
      lp[2] += Bs[5] + t2[2];
      mulT3(acc, R, lp);
      mulT3(acc + 3, R, Bs);
      cross3(tmp, wv, vr);
      mulT3(ach, R, ac);
      acc[0] -= tmp[0] + ach[0];
      acc[1] -= tmp[1] + ach[1];
      acc[2] -= tmp[2] + ach[2];
      if (hb->diag_am) {
        for (int i = 0; i < 6; i++) tau[i] -= A[7 * i] * acc[i];
      } else {
        for (int i = 0; i < 6; i++) {
          double sum = 0.0;
          for (int k = 0; k < 6; k++) sum += A[6 * i + k] * acc[k];
          tau[i] -= sum;
        }
      }
      if (add_mass) {
        /* d->M += J^T M_A J over the body's chain: column a of J is (R^T (cdof_lin +
         * cdof_ang x off), R^T cdof_ang) of dof chain[a]; the CSR row of chain[a] holds exactly
         * chain[0..a] (checked at init), so entry (a, c) is at M_rowadr[chain[a]] + c */
        const int nc = hb->nc;
        const int* chain = hb->chain;
        double* J = w->J;
        double* W = w->W;
        for (int a = 0; a < nc; a++) {
          const double* cd = d->cdof + 6 * chain[a];
          double cp[3];
          cross3(cp, cd, off);
          cp[0] += cd[3];
          cp[1] += cd[4];
          cp[2] += cd[5];
          double* Ja = J + 6 * a;
          mulT3(Ja, R, cp);
          mulT3(Ja + 3, R, cd);
          double* Wa = W + 6 * a;
          if (hb->diag_am) {
            for (int k = 0; k < 6; k++) Wa[k] = A[7 * k] * Ja[k];
          } else {
            for (int k = 0; k < 6; k++) {
              const double* Ak = A + 6 * k;
              Wa[k] = Ak[0] * Ja[0] + Ak[1] * Ja[1] + Ak[2] * Ja[2] + Ak[3] * Ja[3] +
                      Ak[4] * Ja[4] + Ak[5] * Ja[5];
            }
          }
        }
        mjtNum* M = d->M;
        for (int a = 0; a < nc; a++) {
          const double* Ja = J + 6 * a;
          const double j0 = Ja[0], j1 = Ja[1], j2 = Ja[2], j3 = Ja[3], j4 = Ja[4], j5 = Ja[5];
          mjtNum* Mrow = M + m->M_rowadr[chain[a]];
          for (int c = 0; c <= a; c++) {
            const double* Wc = W + 6 * c;
            Mrow[c] += j0 * Wc[0] + j1 * Wc[1] + j2 * Wc[2] + j3 * Wc[3] + j4 * Wc[4] + j5 * Wc[5];
          }
        }
      }
    }

    if (use_damp) {
      for (int i = 0; i < 6; i++) tau[i] -= (hb->DL[i] + hb->DQ[i] * fabs(nur[i])) * nur[i];
    }

    if (use_strip) {
      const double half_rho = 0.5 * rho;
      for (int k = 0; k < hb->nstrip; k++) {
        const strip_t* st = hb->strips + k;
        int ax = st->axis;
        double e[3] = {0, 0, 0}, wxe[3];
        e[ax] = 1.0;
        cross3(wxe, wv, e);
        /* waves: the flow of the strip is the current at p plus the waves at the strip's midpoint
         * (uniform along the strip), instead of the waves at p */
        const double* vrs = vr;
        double vrw[3];
        if (w->waves.n) {
          double mid[3], em[3], pm[3], vwm[3], awm[3], dvw[3], dvh[3];
          const double sm = 0.5 * (st->s0 + st->s1);
          em[0] = em[1] = em[2] = 0.0;
          em[ax] = sm;
          mul3(mid, R, em);
          pm[0] = p[0] + mid[0];
          pm[1] = p[1] + mid[1];
          pm[2] = p[2] + mid[2];
          uvms_waves_kinematics(&w->waves, d->time, pm, vwm, awm, NULL);
          for (int c = 0; c < 3; c++) dvw[c] = vwm[c] - vwp[c];
          mulT3(dvh, R, dvw);
          for (int c = 0; c < 3; c++) vrw[c] = vr[c] - dvh[c];
          vrs = vrw;
        }
        int idx = 0;
        for (int n = 0; n < 3; n++) {
          if (n == ax) continue;
          double cd = st->cd[idx++];
          if (cd == 0.0) continue;
          double i0, i1;
          strip_integrals(vrs[n], wxe[n], st->s0, st->s1, &i0, &i1);
          double c = half_rho * cd;
          /* force -c I0 along n; moment about the origin: (e x n) (-c I1) */
          tau[n] -= c * i0;
          double en[3], nn[3] = {0, 0, 0};
          nn[n] = 1.0;
          cross3(en, e, nn);
          tau[3] -= c * i1 * en[0];
          tau[4] -= c * i1 * en[1];
          tau[5] -= c * i1 * en[2];
        }
      }
    }

    /* world force f and torque t about p */
    double f[3], t[3];
    mul3(f, R, tau);
    mul3(t, R, tau + 3);
    if (use_buoy || use_fk) {
      double F[3] = {0, 0, 0};
      const double rv = rho * hb->volume;
      if (use_buoy) {
        F[0] -= rv * g[0];
        F[1] -= rv * g[1];
        F[2] -= rv * g[2];
      }
      if (use_fk) {
        F[0] += rv * ac[0];
        F[1] += rv * ac[1];
        F[2] += rv * ac[2];
      }
      double cw[3], r[3], mom[3];
      mul3(cw, xmat, hb->cob);
      r[0] = cw[0] + xpos[0] - p[0];
      r[1] = cw[1] + xpos[1] - p[1];
      r[2] = cw[2] + xpos[2] - p[2];
      cross3(mom, r, F);
      for (int i = 0; i < 3; i++) {
        f[i] += F[i];
        t[i] += mom[i];
      }
    }
    /* as a spatial force at the centre of mass: (t + (p - com) x f, f); qfrc = cdof . that,
     * which is mj_applyFT's J^T (f, t) */
    double* Fk = Fb + 6 * b;
    double tm[3];
    cross3(tm, off, f);
    Fk[0] += t[0] + tm[0];
    Fk[1] += t[1] + tm[1];
    Fk[2] += t[2] + tm[2];
    Fk[3] += f[0];
    Fk[4] += f[1];
    Fk[5] += f[2];
  }

  /* backward pass (children first): subtree sums */
  for (int ia = nactive - 1; ia >= 0; ia--) {
    const int k = active[ia];
    const int par = m->body_parentid[k];
    if (par <= 0) continue;
    double* Fp = Fb + 6 * par;
    const double* Fk = Fb + 6 * k;
    for (int c = 0; c < 6; c++) Fp[c] += Fk[c];
  }

  /* generalized forces: qfrc_passive[i] += cdof_i . F(subtree of the body of dof i) */
  for (int ii = 0; ii < w->nfdof; ii++) {
    const int i = w->fdof[ii];
    const double* cd = d->cdof + 6 * i;
    const double* F = Fb + 6 * m->dof_bodyid[i];
    d->qfrc_passive[i] += cd[0] * F[0] + cd[1] * F[1] + cd[2] * F[2] + cd[3] * F[3] + cd[4] * F[4] +
                          cd[5] * F[5];
  }

  if (add_mass) {
    mj_factorM(m, d);
    if (d->nefc) mj_projectConstraint(m, d);
    memcpy(w->Mcopy, d->M, sizeof(mjtNum) * (size_t)m->nC);
    w->Mvalid = 1;
  }
}

/* ------------------------------------------------------------------ uvms.hydro callbacks */

static int hydro_nstate(const mjModel* m, int instance) { return 0; }

static int hydro_init(const mjModel* m, mjData* d, int instance) {
  int wslot = find_slot("uvms.water");
  int found = 0;
  for (int i = 0; i < m->nplugin; i++)
    if (wslot >= 0 && m->plugin[i] == wslot) found = 1;
  int body = -1;
  for (int b = 0; b < m->nbody; b++)
    if (m->body_plugin[b] == instance) body = b;
  if (body < 0) {
    const char* name = mj_id2name(m, mjOBJ_PLUGIN, instance);
    mju_error("uvms.hydro: instance '%s' is not attached to a body; put <plugin "
              "plugin=\"uvms.hydro\"><config .../></plugin> inside the <body>",
              name ? name : "?");
    return -1;
  }
  if (!found) {
    char label[256];
    body_label(m, body, label, sizeof(label));
    mju_error("uvms.hydro: %s has uvms.hydro parameters but the model has no uvms.water "
              "instance; add <extension><plugin plugin=\"uvms.water\"><instance name=\"water\"/>"
              "</plugin><plugin plugin=\"uvms.hydro\"/></extension>", label);
    return -1;
  }
  d->plugin_data[instance] = 0;
  return 0;
}

static void hydro_reset(const mjModel* m, mjtNum* s, void* plugin_data, int instance) {}

static void hydro_compute(const mjModel* m, mjData* d, int instance, int capability_bit) {}

/* ------------------------------------------------------------------ registration */

mjPLUGIN_LIB_INIT(uvms_water_hydro) {
  mjpPlugin p;
  mjp_defaultPlugin(&p);
  p.name = "uvms.water";
  p.capabilityflags |= mjPLUGIN_PASSIVE;
  p.nattribute = WATER_NATTR;
  p.attributes = water_attributes;
  p.nstate = water_nstate;
  p.init = water_init;
  p.destroy = water_destroy;
  p.copy = water_copy;
  p.reset = water_reset;
  p.compute = water_compute;
  p.advance = water_advance;
  mjp_registerPlugin(&p);

  mjpPlugin q;
  mjp_defaultPlugin(&q);
  q.name = "uvms.hydro";
  q.capabilityflags |= mjPLUGIN_PASSIVE;
  q.nattribute = HYDRO_NATTR;
  q.attributes = hydro_attributes;
  q.nstate = hydro_nstate;
  q.init = hydro_init;
  q.reset = hydro_reset;
  q.compute = hydro_compute;
  mjp_registerPlugin(&q);
}
