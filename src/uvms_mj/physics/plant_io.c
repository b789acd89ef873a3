// One control sample of a plant's input and output, compiled (uvms_mj/physics/plant_io.py).
//
// What Plant.step_observe does in Python -- save the state, take n steps (mj_step), check the
// result (no MuJoCo reset: the clock went on by n steps; a finite state below max_speed in
// sum |qvel|), read the new state (qpos, qvel, the tip site on a scratch mjData after
// mj_kinematics, the thrusters' lag states clamped to their force ranges) -- in one call. Returns 0 when all is well (the readout is in `out`), 1 when the batch shows a problem:
// the caller then restores `snap` and replays the steps one by one to report where it happened.

#include <math.h>

#include <mujoco/mujoco.h>

int uvms_plant_step_observe(const mjModel* m, mjData* d, mjData* scratch, int n, double* snap, int snap_spec,
                            double max_speed, int tip_site, int ntip, int nthr, const int* thr_act,
                            const double* lo, const double* hi, double* out) {
  mj_getState(m, d, snap, snap_spec);
  double dt = m->opt.timestep;
  double t_end = d->time + n * dt;
  for (int i = 0; i < n; i++) mj_step(m, d);
  if (!(fabs(d->time - t_end) < 0.5 * dt)) return 1;  // a MuJoCo reset restarts time
  double speed = 0.0, qsum = 0.0;  // the sums of Plant._check_state, in the same order
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
