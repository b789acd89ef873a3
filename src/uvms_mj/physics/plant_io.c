// One control sample of a plant's input and output, compiled (uvms_mj/physics/plant_io.py).
//
// What Plant.step_observe does in Python -- save the state, take n steps (mj_step), check the
// result (no MuJoCo reset: the clock went on by n steps; a finite state below max_speed in
// sum |qvel|), read the new state (qpos, qvel, the tip site on a scratch mjData after
// mj_kinematics, the thrusters' lag states clamped to their force ranges) -- in one call.
// Returns 0 when all is well (the readout is in `out`); 1 when the batch shows a problem (the
// caller restores `snap` and replays the steps one by one to report where it happened); 2 when
// the state was already bad before the steps (nothing done: the caller steps as Plant.step does).

#include <math.h>

#include <mujoco/mujoco.h>

typedef struct {
  const mjModel* m;
  mjData* d;
  mjData* scratch;
  double* snap;
  int snap_spec, tip_site, ntip, nthr;
  const int* thr_act;
  const double *lo, *hi;
  double* out;
} uvms_plant_io;

int uvms_plant_step_observe(const uvms_plant_io* io, int n, double max_speed) {
  const mjModel* m = io->m;
  mjData* d = io->d;
  mjData* scratch = io->scratch;
  double* snap = io->snap;
  int snap_spec = io->snap_spec, tip_site = io->tip_site, ntip = io->ntip, nthr = io->nthr;
  const int* thr_act = io->thr_act;
  const double *lo = io->lo, *hi = io->hi;
  double* out = io->out;
  double speed = 0.0, qsum = 0.0;  // the sums of Plant._check_state, in the same order
  for (int i = 0; i < m->nv; i++) speed += fabs(d->qvel[i]);
  for (int i = 0; i < m->nq; i++) qsum += d->qpos[i];
  if (!(speed <= max_speed && isfinite(qsum))) return 2;  // a bad state before the steps: not stepped
  mj_getState(m, d, snap, snap_spec);
  double dt = m->opt.timestep;
  double t_end = d->time + n * dt;
  for (int i = 0; i < n; i++) mj_step(m, d);
  if (!(fabs(d->time - t_end) < 0.5 * dt)) return 1;  // a MuJoCo reset restarts time
  speed = 0.0;
  qsum = 0.0;
  for (int i = 0; i < m->nv; i++) speed += fabs(d->qvel[i]);
  for (int i = 0; i < m->nq; i++) qsum += d->qpos[i];
  if (!(speed <= max_speed && isfinite(qsum))) return 1;
  double* o = out;
  mju_copy(o, d->qpos, m->nq);
  o += m->nq;
  mju_copy(o, d->qvel, m->nv);
  o += m->nv;
  if (ntip) {
    mju_copy(scratch->qpos, d->qpos, m->nq);
    mj_kinematics(m, scratch);
    mju_copy(o, scratch->site_xpos + 3 * tip_site, ntip);
    o += ntip;
  }
  for (int i = 0; i < nthr; i++) {
    double a = d->act[thr_act[i]];
    o[i] = a < lo[i] ? lo[i] : (a > hi[i] ? hi[i] : a);
  }
  return 0;
}
