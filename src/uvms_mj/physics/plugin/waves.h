/*
 * Linear (Airy) water waves for the `uvms.water` plugin: regular waves and irregular seas from a
 * JONSWAP or Pierson-Moskowitz spectrum, finite or deep water (docs/hydrodynamics.md, "Waves").
 * uvms_mj.physics.waves is the numpy implementation of the same rules (tests compare them).
 */
#ifndef UVMS_WAVES_H
#define UVMS_WAVES_H

#include <stddef.h>
#include <stdint.h>

enum { WAVES_NONE = 0, WAVES_AIRY = 1, WAVES_JONSWAP = 2, WAVES_PM = 3 };

/* Default number of components of an irregular sea, and the frequency band [lo, hi] omega_p. */
#define WAVES_DEFAULT_COMPONENTS 100
#define WAVES_BAND_LO 0.5
#define WAVES_BAND_HI 4.0
#define WAVES_MAX_SPREADING 100.0
#define WAVES_MAX_COMPONENTS 10000

typedef struct {
  int model;           /* WAVES_* */
  double height;       /* airy: wave height H = 2a [m]; spectra: significant wave height Hs [m] */
  double period;       /* airy: period T [s]; spectra: peak period Tp [s] */
  double gamma;        /* JONSWAP peak enhancement factor (1..7) */
  double direction;    /* mean direction of travel, world, from +x towards +y [rad] */
  double spreading;    /* cos^n spreading exponent n >= 0 (0: long-crested) */
  double depth;        /* water depth h > 0 [m]; 0: deep water */
  double surface;      /* world height of the mean free surface [m] */
  uint64_t seed;       /* random frequency offsets, phases and directions */
  int ncomp;           /* components of an irregular sea */
} waves_params_t;

typedef struct {
  int n;               /* components (0: no waves) */
  double depth, surface;
  double* c;           /* 7 per component: a, omega, k, cos(theta), sin(theta), phase, spare */
} waves_t;

/* SplitMix64 finaliser (mod 2^64): the counter-based random streams of the water plugin (the
 * Gauss-Markov current's normals, water.c; the waves' offsets, phases and directions, waves.c);
 * uvms_mj.physics.rng.splitmix64 in Python. */
uint64_t uvms_splitmix64(uint64_t z);

/* omega^2 = g k tanh(k h) solved for k (h <= 0: deep water, k = omega^2 / g). */
double uvms_waves_wavenumber(double omega, double depth, double g);
/* the one-sided spectrum S(omega) [m^2 s/rad] of the params (JONSWAP or PM). */
double uvms_waves_spectrum(const waves_params_t* p, double omega);
/* components of the params; returns 0, or -1 with a message in err. */
int uvms_waves_build(const waves_params_t* p, double g, waves_t* w, char* err, size_t nerr);
void uvms_waves_free(waves_t* w);
/* surface elevation eta [m] above the mean surface at the horizontal (x, y), time t */
double uvms_waves_elevation(const waves_t* w, double t, double x, double y);
/* water particle velocity v and local acceleration a = dv/dt (world) at the point p, time t, and
 * (grad not NULL) the velocity gradient grad[3 i + j] = d v_i / d x_j */
void uvms_waves_kinematics(const waves_t* w, double t, const double p[3], double v[3], double a[3],
                           double grad[9]);

#endif
