// uvms.thruster: a MuJoCo actuator plugin for underwater thrusters.
//
// Specification: docs/hydrodynamics.md, section "Thrusters: `uvms.thruster`".
//
//   <extension><plugin plugin="uvms.thruster"/></extension>
//   <actuator>
//     <plugin plugin="uvms.thruster" site="t1" actdim="1" ctrlrange="-1 1"
//             forcerange="-40 50" gear="1 0 0 0 0 0">
//       <config key="curve" value="poly 0 1"/>       <!-- or "table u0 F0 u1 F1 ..." -->
//       <config key="dead_zone" value="-0.05 0.05"/>
//       <config key="tau" value="0.1"/>
//     </plugin>
//   </actuator>
//
// Pipeline of one thruster, from the command u = ctrl to the actuator force:
//   1. u is clamped to ctrlrange (when ctrllimited and mjDSBL_CLAMPCTRL is off). MuJoCo clamps
//      only its private copy of ctrl, which plugins do not see, so the plugin clamps itself.
//      A delayed actuator (`delay`) reads u from the control history (mj_readCtrl), and, as for
//      MuJoCo's own actuators, a bad control anywhere (NaN, |u| > mjMAXVAL) makes u = 0.
//   2. dead zone: dz_lo < u < dz_hi (strictly) gives u = 0.
//   3. lag: tau > 0: the actuator's own activation act (actdim="1") obeys
//      act_dot = (u - act) / tau (`actuator_act_dot` callback); MuJoCo integrates it with the
//      model's integrator (Euler, RK4, implicit, implicitfast), exactly as the act of a
//      <general dyntype="filter" dynprm="tau"> (the tests check bit-identical trajectories).
//      With actearly="true" the force uses the next activation act + h act_dot, as MuJoCo's
//      own filter actuators do. tau = 0: no lag and no state: actdim must be 0 (the default)
//      and the force follows u at once. The actuator's dyntype must stay 'none' (MuJoCo's
//      compiler then also refuses actrange); there is no exact-filter variant.
//   4. curve: F = F(a), a = act (tau > 0) or u (tau = 0): "poly c0 c1 ... cn" is
//      c0 + c1 a + ... + cn a^n (Horner), "table u0 F0 u1 F1 ..." is piecewise linear through
//      the points (u strictly increasing), constant beyond the end points.
//   5. F is written to d->actuator_force[actuator_outadr]; MuJoCo then clamps every
//      actuator_force, plugins' included, to forcerange when forcelimited (mj_fwdActuation,
//      after the plugins' compute), so the plugin does not clamp it a second time; the tests
//      check that clamp. qfrc_actuator = moment^T force is MuJoCo's (site transmission: the
//      thrust acts along the site's x axis with gear "1 0 0 0 0 0").
//   An actuator disabled by its group (mjOption.disableactuator) gives force 0, as MuJoCo's.
//
// One instance may drive several actuators (declare it under <extension> with
// <instance name="T"> and its <config>, and use <actuator><plugin instance="T" site=.../>):
// they share the configuration. The parsed configuration lives in per-mjData plugin data
// (read-only after init); there is no global mutable state, so rollouts on many threads are
// safe.
//
// Bad configuration: init calls mju_error with a message naming the actuator, the attribute,
// the value and what is allowed. It reaches Python as an exception with that message: the
// compiler (init runs while compiling) raises ValueError, mjData creation (e.g. from a binary
// model) mujoco.FatalError. (Returning -1 from init makes MuJoCo's own message, which names
// only the plugin id.)

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

#define THRUSTER_NAME "uvms.thruster"

enum { CURVE_POLY = 0, CURVE_TABLE = 1 };

typedef struct {
  int curve;         // CURVE_POLY or CURVE_TABLE
  int ncurve;        // poly: number of coefficients (degree + 1); table: number of points
  mjtNum* coef;      // poly: c0..cn; table: u0 F0 u1 F1 ... (2 ncurve numbers)
  mjtNum dz_lo;      // dead zone: commands strictly between dz_lo and dz_hi are 0
  mjtNum dz_hi;
  mjtNum tau;        // time constant of the lag (s); 0: no lag
  int nact;          // number of actuators driven by this instance
  int* act;          // their ids
} Thruster;

static const char* kAttributes[] = {"curve", "dead_zone", "tau"};

//---------------------------------- parsing --------------------------------------------------

// name of actuator i for messages
static void actuator_label(const mjModel* m, int i, char* buf, size_t size) {
  const char* name = mj_id2name(m, mjOBJ_ACTUATOR, i);
  if (name && name[0]) {
    snprintf(buf, size, "actuator '%s' (id %d)", name, i);
  } else {
    snprintf(buf, size, "actuator id %d (unnamed)", i);
  }
}

static int is_space(char c) {
  return c == ' ' || c == '\t' || c == '\n' || c == '\r';
}

// parse the whitespace-separated numbers of s into out (at most max; out may be NULL to count);
// returns their count, or -1 at the first token that is not a finite number (NaN, inf, a word),
// which is copied into bad for the message
static int parse_numbers(const char* s, mjtNum* out, int max, char* bad, size_t badsize) {
  int n = 0;
  const char* p = s;
  while (1) {
    while (is_space(*p)) p++;
    if (!*p) break;
    char* end = NULL;
    double v = strtod(p, &end);
    if (end == p || (*end && !is_space(*end)) || !isfinite(v)) {
      const char* q = p;
      while (*q && !is_space(*q)) q++;
      int len = (int)(q - p);
      snprintf(bad, badsize, "%.*s%s", len > 60 ? 60 : len, p, len > 60 ? "..." : "");
      return -1;
    }
    if (out && n < max) out[n] = v;
    n++;
    p = end;
  }
  return n;
}

static void thruster_free(Thruster* t) {
  if (!t) return;
  free(t->coef);
  free(t->act);
  free(t);
}

// failure in thruster_create: the message into err, free t, return NULL
#define FAIL(...)                          \
  do {                                     \
    snprintf(err, errsize, __VA_ARGS__);   \
    thruster_free(t);                      \
    return NULL;                           \
  } while (0)

// parse and validate the configuration of an instance; NULL (with the message in err) if invalid
static Thruster* thruster_create(const mjModel* m, int instance, char* err, size_t errsize) {
  Thruster* t = NULL;
  char label[256] = "";
  char bad[128];

  // actuators of this instance
  int nact = 0;
  for (int i = 0; i < m->nactuator; i++) {
    if (m->actuator_plugin[i] == instance) nact++;
  }
  if (nact == 0) {
    FAIL(THRUSTER_NAME ": plugin instance %d drives no actuator; declare thrusters as "
         "<actuator><plugin plugin=\"" THRUSTER_NAME "\" site=\"...\" .../>", instance);
  }

  t = (Thruster*)calloc(1, sizeof(Thruster));
  if (!t) FAIL(THRUSTER_NAME ": out of memory");
  t->act = (int*)malloc(sizeof(int) * nact);
  if (!t->act) FAIL(THRUSTER_NAME ": out of memory");
  for (int i = 0; i < m->nactuator; i++) {
    if (m->actuator_plugin[i] == instance) t->act[t->nact++] = i;
  }
  actuator_label(m, t->act[0], label, sizeof(label));
  if (nact > 1) {
    size_t len = strlen(label);
    snprintf(label + len, sizeof(label) - len, " and %d more sharing the instance", nact - 1);
  }

  // curve
  const char* curve = mj_getPluginConfig(m, instance, "curve");
  if (!curve || !curve[0]) curve = "poly 0 1";
  {
    const char* p = curve;
    while (is_space(*p)) p++;
    const char* kw = p;
    while (*p && !is_space(*p)) p++;
    size_t kwlen = (size_t)(p - kw);
    if (kwlen == 4 && !strncmp(kw, "poly", 4)) {
      t->curve = CURVE_POLY;
    } else if (kwlen == 5 && !strncmp(kw, "table", 5)) {
      t->curve = CURVE_TABLE;
    } else {
      FAIL(THRUSTER_NAME ", %s: attribute 'curve' = \"%s\": unknown keyword '%.*s'; "
           "allowed: \"poly c0 c1 ... cn\" or \"table u0 F0 u1 F1 ...\"",
           label, curve, (int)kwlen, kw);
    }
    int n = parse_numbers(p, NULL, 0, bad, sizeof(bad));
    if (n < 0) {
      FAIL(THRUSTER_NAME ", %s: attribute 'curve' = \"%s\": '%s' is not a finite "
           "number", label, curve, bad);
    }
    if (t->curve == CURVE_POLY && n < 1) {
      FAIL(THRUSTER_NAME ", %s: attribute 'curve' = \"%s\": a polynomial needs at "
           "least one coefficient (\"poly c0 c1 ... cn\")", label, curve);
    }
    if (t->curve == CURVE_TABLE && (n < 2 || n % 2)) {
      FAIL(THRUSTER_NAME ", %s: attribute 'curve' = \"%s\": a table needs pairs "
           "\"u0 F0 u1 F1 ...\" (at least one point), got %d numbers", label, curve, n);
    }
    t->coef = (mjtNum*)malloc(sizeof(mjtNum) * n);
    if (!t->coef) {
      FAIL(THRUSTER_NAME ": out of memory");
    }
    parse_numbers(p, t->coef, n, bad, sizeof(bad));
    t->ncurve = (t->curve == CURVE_POLY) ? n : n / 2;
    if (t->curve == CURVE_TABLE) {
      for (int k = 1; k < t->ncurve; k++) {
        if (!(t->coef[2*k] > t->coef[2*k - 2])) {
          FAIL(THRUSTER_NAME ", %s: attribute 'curve' = \"%s\": the table's u must be "
               "strictly increasing, but u%d = %g follows u%d = %g", label, curve,
               k, t->coef[2*k], k - 1, t->coef[2*k - 2]);
        }
      }
    }
  }

  // dead zone
  const char* dz = mj_getPluginConfig(m, instance, "dead_zone");
  if (dz && dz[0]) {
    mjtNum v[2];
    int n = parse_numbers(dz, v, 2, bad, sizeof(bad));
    if (n < 0) {
      FAIL(THRUSTER_NAME ", %s: attribute 'dead_zone' = \"%s\": '%s' is not a finite "
           "number; allowed: two numbers \"dz_lo dz_hi\" with dz_lo <= dz_hi",
           label, dz, bad);
    }
    if (n != 2) {
      FAIL(THRUSTER_NAME ", %s: attribute 'dead_zone' = \"%s\": expected two numbers "
           "\"dz_lo dz_hi\" with dz_lo <= dz_hi, got %d", label, dz, n);
    }
    if (v[0] > v[1]) {
      FAIL(THRUSTER_NAME ", %s: attribute 'dead_zone' = \"%s\": dz_lo = %g > dz_hi = "
           "%g; allowed: dz_lo <= dz_hi", label, dz, v[0], v[1]);
    }
    t->dz_lo = v[0];
    t->dz_hi = v[1];
  }

  // tau
  const char* tau = mj_getPluginConfig(m, instance, "tau");
  if (tau && tau[0]) {
    mjtNum v[1];
    int n = parse_numbers(tau, v, 1, bad, sizeof(bad));
    if (n < 0) {
      FAIL(THRUSTER_NAME ", %s: attribute 'tau' = \"%s\": '%s' is not a finite number; "
           "allowed: one number tau >= 0 (s)", label, tau, bad);
    }
    if (n != 1) {
      FAIL(THRUSTER_NAME ", %s: attribute 'tau' = \"%s\": expected one number "
           "tau >= 0 (s), got %d", label, tau, n);
    }
    if (v[0] < 0) {
      FAIL(THRUSTER_NAME ", %s: attribute 'tau' = \"%s\": tau = %g < 0; allowed: "
           "tau >= 0 (s; 0: no lag)", label, tau, v[0]);
    }
    t->tau = v[0];
  }

  // the actuators: one control, one force output, activation dimension matching tau
  for (int j = 0; j < t->nact; j++) {
    int i = t->act[j];
    actuator_label(m, i, label, sizeof(label));
    if (m->actuator_ctrlnum[i] != 1 || m->actuator_outnum[i] != 1) {
      FAIL(THRUSTER_NAME ", %s: a thruster has one control and one force output, "
           "this transmission has %d and %d; use a site, joint or tendon transmission",
           label, m->actuator_ctrlnum[i], m->actuator_outnum[i]);
    }
    if (m->actuator_dyntype[i] != mjDYN_NONE) {
      FAIL(THRUSTER_NAME ", %s: dyntype must be 'none' (the plugin computes its own "
           "activation dynamics from 'tau')", label);
    }
    int actnum = m->actuator_actnum[i];
    if (t->tau > 0 && actnum != 1) {
      FAIL(THRUSTER_NAME ", %s: attribute 'tau' = %g > 0 needs the lag state: set "
           "actdim=\"1\" on the actuator (it has actdim %d)", label, t->tau, actnum);
    }
    if (t->tau == 0 && actnum != 0) {
      FAIL(THRUSTER_NAME ", %s: attribute 'tau' = 0 (no lag) has no state: set "
           "actdim=\"0\" on the actuator, or give tau > 0 (it has actdim %d)",
           label, actnum);
    }
  }
  return t;
}

#undef FAIL

//---------------------------------- evaluation -----------------------------------------------

// thrust curve F(a)
static mjtNum thruster_curve(const Thruster* t, mjtNum a) {
  const mjtNum* c = t->coef;
  int n = t->ncurve;
  if (t->curve == CURVE_POLY) {
    mjtNum f = c[n - 1];
    for (int k = n - 2; k >= 0; k--) {
      f = f * a + c[k];
    }
    return f;
  }
  // table: constant beyond the ends, linear in between
  if (a <= c[0]) return c[1];
  if (a >= c[2*(n - 1)]) return c[2*(n - 1) + 1];
  int lo = 0, hi = n - 1;  // c[2 lo] <= a < c[2 hi]
  while (hi - lo > 1) {
    int mid = (lo + hi) / 2;
    if (a < c[2*mid]) {
      hi = mid;
    } else {
      lo = mid;
    }
  }
  mjtNum u0 = c[2*lo], f0 = c[2*lo + 1], u1 = c[2*hi], f1 = c[2*hi + 1];
  return f0 + (f1 - f0) * ((a - u0) / (u1 - u0));
}

// is actuator i disabled by its group (mjOption.disableactuator)?
static int actuator_disabled(const mjModel* m, int i) {
  int group = m->actuator_group[i];
  if (group < 0 || group > 30) return 0;
  return (m->opt.disableactuator & (1 << group)) ? 1 : 0;
}

// command of actuator i after the ctrlrange clamp and the dead zone
static mjtNum thruster_command(const Thruster* t, const mjModel* m, const mjData* d, int i) {
  int adr = m->actuator_ctrladr[i];
  mjtNum u;
  if (m->actuator_delay[i] > 0) {
    mjtNum buf;
    const mjtNum* p = mj_readCtrl(m, d, i, d->time, &buf, m->actuator_history[2*i + 1]);
    u = p ? *p : buf;
  } else {
    u = d->ctrl[adr];
  }
  int clampall = !(m->opt.disableflags & mjDSBL_CLAMPCTRL);
  if (clampall && m->actuator_ctrllimited[adr]) {
    u = mju_clip(u, m->actuator_ctrlrange[2*adr], m->actuator_ctrlrange[2*adr + 1]);
  }

  // as MuJoCo: a bad control anywhere zeroes all controls (its own warning is raised there)
  if (mju_isBad(u)) return 0;
  for (int k = 0; k < m->nu; k++) {
    mjtNum v = d->ctrl[k];
    if (clampall && m->actuator_ctrllimited[k]) {
      v = mju_clip(v, m->actuator_ctrlrange[2*k], m->actuator_ctrlrange[2*k + 1]);
    }
    if (mju_isBad(v)) return 0;
  }

  if (u > t->dz_lo && u < t->dz_hi) u = 0;
  return u;
}

//---------------------------------- callbacks ------------------------------------------------

static int thruster_nstate(const mjModel* m, int instance) {
  return 0;
}

static int thruster_init(const mjModel* m, mjData* d, int instance) {
  char err[1024] = "";
  Thruster* t = thruster_create(m, instance, err, sizeof(err));
  if (!t) {
    // mju_error, not mju_warning + return -1: the message itself becomes the exception
    // (ValueError from the compiler, mujoco.FatalError from MjData); MuJoCo's own message for
    // a failed init names only the plugin id
    mju_error("%s", err);
    return -1;
  }
  d->plugin_data[instance] = (uintptr_t)t;
  return 0;
}

static void thruster_destroy(mjData* d, int instance) {
  thruster_free((Thruster*)d->plugin_data[instance]);
  d->plugin_data[instance] = 0;
}

static void thruster_reset(const mjModel* m, mjtNum* plugin_state, void* plugin_data,
                           int instance) {
  // no plugin state; the lag state is mjData.act, reset by MuJoCo
}

static void thruster_act_dot(const mjModel* m, mjData* d, int instance) {
  const Thruster* t = (const Thruster*)d->plugin_data[instance];
  if (!t || t->tau <= 0) return;
  for (int j = 0; j < t->nact; j++) {
    int i = t->act[j];
    int adr = m->actuator_actadr[i];
    mjtNum u = thruster_command(t, m, d, i);
    d->act_dot[adr] = (u - d->act[adr]) / t->tau;
  }
}

static void thruster_compute(const mjModel* m, mjData* d, int instance, int capability_bit) {
  const Thruster* t = (const Thruster*)d->plugin_data[instance];
  if (!t) {
    mju_error(THRUSTER_NAME ": plugin instance %d has no data (init was not called)", instance);
    return;
  }
  for (int j = 0; j < t->nact; j++) {
    int i = t->act[j];
    int out = m->actuator_outadr[i];
    if (actuator_disabled(m, i)) {
      d->actuator_force[out] = 0;
      continue;
    }
    mjtNum a;
    if (t->tau > 0) {
      int adr = m->actuator_actadr[i];
      a = d->act[adr];
      if (m->actuator_actearly[i]) {
        // next activation, as MuJoCo's own actuators with dyntype none (Euler)
        a = a + d->act_dot[adr] * m->opt.timestep;
        if (m->actuator_actlimited[i]) {
          a = mju_clip(a, m->actuator_actrange[2*i], m->actuator_actrange[2*i + 1]);
        }
      }
    } else {
      a = thruster_command(t, m, d, i);
    }
    // forcerange: clamped by MuJoCo after this callback (mj_fwdActuation)
    d->actuator_force[out] = thruster_curve(t, a);
  }
}

mjPLUGIN_LIB_INIT(uvms_thruster) {
  mjpPlugin plugin;
  mjp_defaultPlugin(&plugin);
  plugin.name = THRUSTER_NAME;
  plugin.capabilityflags |= mjPLUGIN_ACTUATOR;
  plugin.nattribute = sizeof(kAttributes) / sizeof(kAttributes[0]);
  plugin.attributes = kAttributes;
  plugin.nstate = thruster_nstate;
  plugin.init = thruster_init;
  plugin.destroy = thruster_destroy;
  plugin.reset = thruster_reset;
  plugin.compute = thruster_compute;
  plugin.actuator_act_dot = thruster_act_dot;
  mjp_registerPlugin(&plugin);
}
