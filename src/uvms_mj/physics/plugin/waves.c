/*
 * Linear (Airy) water waves for the `uvms.water` plugin (waves.h; docs/hydrodynamics.md,
 * "Waves"; the numpy twin is uvms_mj.physics.waves).
 *
 * A sea is a sum of components i = 1..n, each with amplitude a, angular frequency omega,
 * wavenumber k (the dispersion relation omega^2 = g k tanh(k h), Faltinsen 1990 table 2.1,
 * DNV-RP-C205 sec. 3.2.2; deep water: omega^2 = g k), direction theta (of travel, world, from +x
 * towards +y) and phase phi; with the phase psi = k (x cos theta + y sin theta) - omega t + phi and
 * zeta = z - surface (<= 0 in the water), the linear potential-flow kinematics are
 * (Faltinsen 1990 table 2.1, DNV-RP-C205 sec. 3.2.2):
 *   eta   = sum a cos psi
 *   u_h   = sum a omega       C(zeta) cos psi        (horizontal, along theta)
 *   w     = sum a omega       S(zeta) sin psi        (vertical)
 *   du_h/dt = sum a omega^2   C(zeta) sin psi,   dw/dt = -sum a omega^2 S(zeta) cos psi
 * with C = cosh(k (zeta + h)) / sinh(k h), S = sinh(k (zeta + h)) / sinh(k h) in finite depth h,
 * evaluated as (e^{k zeta} +- e^{-k (zeta + 2h)}) / (1 - e^{-2 k h}) (no overflow), and
 * C = S = e^{k zeta} in deep water. Below the seabed zeta is clamped to -h.
 *
 * Components (the discretisation rule):
 *   airy: one component, a = H/2, omega = 2 pi / T, theta = direction, phi = 0 (a crest at the
 *     world origin at t = 0);
 *   jonswap, pierson_moskowitz: n components at equal spacing with random offsets over
 *     [WAVES_BAND_LO, WAVES_BAND_HI] omega_p: d_omega = (HI - LO) omega_p / n,
 *     omega_i = LO omega_p + (i + u_i0) d_omega, a_i = sqrt(2 S(omega_i) d_omega),
 *     phi_i = 2 pi u_i1, theta_i = direction + delta_i, delta_i drawn from the cos^n spreading
 *     D(delta) ~ cos^n(delta), |delta| <= pi/2, by rejection: for j = 0, 1, ...:
 *     delta = pi (u_{i,2+2j} - 1/2), accepted when u_{i,3+2j} <= cos(delta)^n (at most 2000
 *     tries, then delta = 0); n = 0: delta = 0 (long-crested).
 *     u_ic = (splitmix64(seed ^ splitmix64(4096 i + c)) >> 11) 2^-53 in [0, 1).
 *   Spectra (DNV-RP-C205 sec. 3.5.5): omega_p = 2 pi / Tp,
 *     S_PM(omega) = 5/16 Hs^2 omega_p^4 omega^-5 exp(-5/4 (omega / omega_p)^-4),
 *     S_J(omega) = A_gamma S_PM(omega) gamma^exp(-(omega - omega_p)^2 / (2 sigma^2 omega_p^2)),
 *     sigma = 0.07 (omega <= omega_p), 0.09 (omega > omega_p), A_gamma = 1 - 0.287 ln(gamma).
 */
#include "waves.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define WAVES_NC 7

uint64_t uvms_splitmix64(uint64_t z) {
  z += 0x9E3779B97F4A7C15ULL;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

/* uniform number c of component i of the stream seed, in [0, 1) */
static double wv_uniform(uint64_t seed, uint64_t i, uint64_t c) {
  return (double)(uvms_splitmix64(seed ^ uvms_splitmix64(4096 * i + c)) >> 11) * 0x1p-53;
}

double uvms_waves_wavenumber(double omega, double depth, double g) {
  double k0 = omega * omega / g;
  if (!(depth > 0.0)) return k0;
  /* x tanh x = y with x = k h, y = k0 h: Newton from Eckart's x = y / sqrt(tanh y) */
  double y = k0 * depth;
  double x = y / sqrt(tanh(y));
  for (int it = 0; it < 100; it++) {
    double th = tanh(x);
    double f = x * th - y;
    double df = th + x * (1.0 - th * th);
    double dx = f / df;
    x -= dx;
    if (fabs(dx) <= 1e-16 * x) break;
  }
  return x / depth;
}

double uvms_waves_spectrum(const waves_params_t* p, double omega) {
  if (!(omega > 0.0)) return 0.0;
  double wp = 2.0 * M_PI / p->period;
  double r = wp / omega;
  double r4 = r * r * r * r;
  double s = 5.0 / 16.0 * p->height * p->height * wp * wp * wp * wp / (omega * omega * omega * omega * omega) *
             exp(-1.25 * r4);
  if (p->model == WAVES_JONSWAP) {
    double sig = omega <= wp ? 0.07 : 0.09;
    double q = (omega - wp) / (sig * wp);
    s *= (1.0 - 0.287 * log(p->gamma)) * pow(p->gamma, exp(-0.5 * q * q));
  }
  return s;
}

int uvms_waves_build(const waves_params_t* p, double g, waves_t* w, char* err, size_t nerr) {
  memset(w, 0, sizeof(*w));
  w->depth = p->depth > 0.0 ? p->depth : 0.0;
  w->surface = p->surface;
  if (p->model == WAVES_NONE) return 0;
  if (!(g > 0.0)) {
    snprintf(err, nerr, "waves need gravity along -z (opt.gravity = (0, 0, -g), g > 0)");
    return -1;
  }
  int n = p->model == WAVES_AIRY ? 1 : p->ncomp;
  w->c = (double*)calloc((size_t)WAVES_NC * (size_t)n, sizeof(double));
  if (!w->c) {
    snprintf(err, nerr, "out of memory");
    return -1;
  }
  w->n = n;
  double wp = 2.0 * M_PI / p->period;
  double dw = (WAVES_BAND_HI - WAVES_BAND_LO) * wp / n;
  for (int i = 0; i < n; i++) {
    double a, om, ph = 0.0, dth = 0.0;
    if (p->model == WAVES_AIRY) {
      a = 0.5 * p->height;
      om = wp;
    } else {
      om = WAVES_BAND_LO * wp + ((double)i + wv_uniform(p->seed, i, 0)) * dw;
      a = sqrt(2.0 * uvms_waves_spectrum(p, om) * dw);
      ph = 2.0 * M_PI * wv_uniform(p->seed, i, 1);
      if (p->spreading > 0.0) {
        for (int j = 0; j < 2000; j++) {
          double d = M_PI * (wv_uniform(p->seed, i, 2 + 2 * (uint64_t)j) - 0.5);
          if (wv_uniform(p->seed, i, 3 + 2 * (uint64_t)j) <= pow(cos(d), p->spreading)) {
            dth = d;
            break;
          }
        }
      }
    }
    double th = p->direction + dth;
    double k = uvms_waves_wavenumber(om, w->depth, g);
    double* c = w->c + WAVES_NC * i;
    c[0] = a;
    c[1] = om;
    c[2] = k;
    c[3] = cos(th);
    c[4] = sin(th);
    c[5] = ph;
    c[6] = w->depth > 0.0 ? 1.0 / (1.0 - exp(-2.0 * k * w->depth)) : 1.0;
  }
  return 0;
}

void uvms_waves_free(waves_t* w) {
  if (!w) return;
  free(w->c);
  w->c = NULL;
  w->n = 0;
}

double uvms_waves_elevation(const waves_t* w, double t, double x, double y) {
  double eta = 0.0;
  for (int i = 0; i < w->n; i++) {
    const double* c = w->c + WAVES_NC * i;
    eta += c[0] * cos(c[2] * (x * c[3] + y * c[4]) - c[1] * t + c[5]);
  }
  return eta;
}

void uvms_waves_kinematics(const waves_t* w, double t, const double p[3], double v[3], double a[3],
                           double grad[9]) {
  double vh[2] = {0, 0}, vz = 0.0, ah[2] = {0, 0}, az = 0.0;
  double gA[3] = {0, 0, 0}, gB[2] = {0, 0}, gC = 0.0; /* sums for the gradient (below) */
  double zeta = p[2] - w->surface;
  const double h = w->depth;
  if (h > 0.0 && zeta < -h) zeta = -h;
  for (int i = 0; i < w->n; i++) {
    const double* c = w->c + WAVES_NC * i;
    const double k = c[2], om = c[1];
    double psi = k * (p[0] * c[3] + p[1] * c[4]) - om * t + c[5];
    double cp = cos(psi), sp = sin(psi);
    double C, S;
    if (h > 0.0) {
      double e1 = exp(k * zeta), e2 = exp(-k * (zeta + 2.0 * h));
      C = (e1 + e2) * c[6];
      S = (e1 - e2) * c[6];
    } else {
      C = S = exp(k * zeta);
    }
    double aw = c[0] * om, aw2 = aw * om;
    double uh = aw * C * cp, dh = aw2 * C * sp;
    vh[0] += uh * c[3];
    vh[1] += uh * c[4];
    ah[0] += dh * c[3];
    ah[1] += dh * c[4];
    vz += aw * S * sp;
    az -= aw2 * S * cp;
    if (grad) {
      /* A = a omega k C sin psi, B = a omega k S cos psi: du_h/dx_j = -A d_j, du_h/dz = B,
       * dw/dx_j = B d_j, dw/dz = A (d = (cos theta, sin theta); dC/dz = k S, dS/dz = k C) */
      double A = aw * k * C * sp, B = aw * k * S * cp;
      gA[0] += A * c[3] * c[3];
      gA[1] += A * c[3] * c[4];
      gA[2] += A * c[4] * c[4];
      gB[0] += B * c[3];
      gB[1] += B * c[4];
      gC += A;
    }
  }
  v[0] = vh[0];
  v[1] = vh[1];
  v[2] = vz;
  a[0] = ah[0];
  a[1] = ah[1];
  a[2] = az;
  if (grad) { /* grad[3 i + j] = d v_i / d x_j (symmetric: the flow is irrotational) */
    grad[0] = -gA[0];
    grad[1] = grad[3] = -gA[1];
    grad[4] = -gA[2];
    grad[2] = grad[6] = gB[0];
    grad[5] = grad[7] = gB[1];
    grad[8] = gC;
  }
}

/* For tests and logging (ctypes): build the sea of the params and evaluate it at npts (t, x, y,
 * z) rows of pts into out (16 per row: eta at (x, y), v (3), dv/dt (3), grad v (9, row-major));
 * returns 0 or -1 (err). */
int uvms_waves_eval(int model, double height, double period, double gamma, double direction,
                    double spreading, double depth, double surface, uint64_t seed, int ncomp, double g,
                    int npts, const double* pts, double* out, char* err, size_t nerr) {
  waves_params_t p = {model, height, period, gamma, direction, spreading, depth, surface, seed, ncomp};
  waves_t w;
  if (uvms_waves_build(&p, g, &w, err, nerr)) return -1;
  for (int r = 0; r < npts; r++) {
    const double* q = pts + 4 * r;
    double* o = out + 16 * r;
    o[0] = uvms_waves_elevation(&w, q[0], q[1], q[2]);
    uvms_waves_kinematics(&w, q[0], q + 1, o + 1, o + 4, o + 7);
  }
  uvms_waves_free(&w);
  return 0;
}

/* For tests: the components (7 per component, as waves_t.c) into out (room for max); returns n. */
int uvms_waves_components(int model, double height, double period, double gamma, double direction,
                          double spreading, double depth, uint64_t seed, int ncomp, double g, double* out,
                          int max) {
  waves_params_t p = {model, height, period, gamma, direction, spreading, depth, 0.0, seed, ncomp};
  waves_t w;
  char err[200];
  if (uvms_waves_build(&p, g, &w, err, sizeof(err))) return -1;
  int n = w.n < max ? w.n : max;
  memcpy(out, w.c, sizeof(double) * WAVES_NC * (size_t)n);
  uvms_waves_free(&w);
  return n;
}
