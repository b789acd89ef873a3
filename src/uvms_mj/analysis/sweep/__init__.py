"""Parameter sweeps: many runs of one scenario over sampled parameters, in parallel, resumable.

``uvms-mj sweep SCENARIO --vary KEY.PATH=SPEC ... [--n N] [--controllers rac,rac_dob]`` runs
the scenario once per sample and controller and writes a results table and summary figures.
Library use::

    plan = plan_sweep("scenarios/paper.yaml", ["plant.current[0]=uniform(0, 0.1)"], n=50)
    outcome = run_sweep(plan, "logs/paper-sweep", workers=2)
    outcome.rows, outcome.summary, outcome.figures

Keys
----
``KEY.PATH`` is any scenario field (:mod:`uvms_mj.scenario.schema`), checked against the schema before
anything runs: ``plant.current``, ``thrusters.tau``, ``sensors.position_noise``,
``controller.params.gamma``, ``trajectory.cruise_speed``, ... Inside ``plant.overrides`` and
``nominal.overrides`` the rest of the path is one parameter name: on the paper's robot one of
``OVERRIDE_KEYS`` (e.g. ``nominal.overrides.base.added_mass``), on a model-file robot
``<element or role>.<field>`` as in its scenario's overrides (e.g.
``nominal.overrides.bluerov2_hull.added_mass``; ``scale`` of a field the file does not set is
the factor ``"xF"`` of the model's own value); inside ``controller.params`` a parameter of every swept
controller. Not allowed: ``name``, ``description``, ``seed`` (per-run seeds come from
``--seed``), ``controller.name`` (use ``--controllers``) and ``outputs.*`` (the sweep writes
its own).

* ``KEY[i]`` is component i of a vector field (``plant.current[0]``: the current along world
  X); the other components keep the scenario's value.
* ``{a,b,...}`` in a key names several fields that all take the SAME drawn value (one axis):
  ``nominal.overrides.{base,link1,link2}.added_mass=scale(uniform(0.7, 1.3))`` scales the added
  mass of every body by one factor. Quote such an argument in the shell (bash expands braces).

Specs
-----
==================================  ==========================================================
``[a, b, c]``                       grid: these values (YAML; a vector field needs a list per
                                    value, ``plant.current=[[0, 0], [0.1, 0]]``)
``linspace(start, stop, n)``        grid: n evenly spaced values, both ends included
``uniform(low, high)``              random: uniform in [low, high), low < high
``loguniform(low, high)``           random: log-uniform, 0 < low < high
``normal(mean, std)``               random: Gaussian, std > 0 (no truncation: a draw outside
                                    the field's allowed values is an error before any run)
``choice(a, b, ...)``               random: one of the values, equally likely
``scale(SPEC)``                     a factor (grid or random) on the scenario's value of the
                                    field: ``scale(uniform(0.7, 1.3))``; on a vector, every
                                    component by the same factor
``[SPEC_or_value, ...]``            a vector field per component: ``plant.current=[uniform(0,
                                    0.1), 0]``; each component spec is its own axis
``value``                           a single value (a one-point grid; same as ``--set``)
==================================  ==========================================================

Values are YAML scalars (numbers, ``true``/``false``, ``null``, strings; ``on``, ``off``,
``yes``, ``no`` stay strings, e.g. ``plant.hydro.drag=choice(strip, mujoco, off)``); quote a
string that contains a comma or a bracket.

"The scenario's value" for ``scale`` (and the untouched components of ``KEY[i]``) is the value
the run would have without the sweep: the scenario file plus ``--set``, with defaults filled
in (``uvms_mj.scenario.schema.resolved``); for a parameter override not given in the file it is the
model's value: for ``nominal.overrides.*`` the robot model file (what the controller would
use), for ``plant.overrides.*`` the plant's (model file plus the truth differences of
``plant.model_mismatch``). Each column of the results table holds the DRAWN value: the factor
for ``scale`` (column ``scale(KEY)``), the component for ``KEY[i]``.

Samples
-------
Every grid spec is an axis of a Cartesian product (in the order given; the last one varies
fastest); every random spec is drawn independently. The sweep has
``product(grid sizes) x N`` samples: at each grid point, ``N = --n`` samples with fresh random
draws (and fresh simulation seeds). So: grids only, no ``--n``: one run per grid point;
grids only with ``--n 5``: each grid point repeated 5 times with different seeds (matters with
sensor noise); random only: ``--n`` samples (``--n`` is then required); both: ``--n`` random
draws at each grid point.

Reproducibility: sample i (0-based, grid point g, repeat r: i = g * N + r) uses
``SeedSequence(seed).spawn(...)[i]``, spawned again into two: the first draws the sample's
random parameters (in the order of the ``--vary`` options), the second gives the run's
``seed`` (sensor noise). The same arguments give the same parameters and seeds. With several
``--controllers``, every sample is run with each of them (same parameters, same seed): the
pairs give the paired ratio (e.g. rac_dob / rac) of each metric.

Outputs (in ``--out-dir DIR``)
--------------------------
* ``sweep.json``: the sweep definition (base scenario, specs, n, seed, controllers);
* ``runs.jsonl``: one line per finished run, appended as runs finish (the resume record);
* ``results.csv`` (and ``results.parquet`` when pyarrow is installed): one row per run:
  ``run_id, sample, controller, seed``, one column per axis, every metric of
  :func:`uvms_mj.sim.metrics.metrics`, ``status`` (ok | diverged | joint_limit | error | crashed), ``reason``,
  ``t_end`` (simulated time reached), ``wall_s``, ``log`` (MCAP path with ``--logs``, else
  empty), ``values`` (JSON: the value each varied field got), ``sets`` (JSON: the ``--set``
  arguments that reproduce the run with ``uvms-mj run SCENARIO``), ``key``;
* ``summary.json``: per controller the counts and the median and 10-90 % range of each
  metric; per controller pair the paired ratio's median and 10-90 % range;
* ``sweep_metrics.png``: base position, attitude and tip RMS against each axis, per
  controller, and their distributions; ``sweep_ratio.png`` (two or more controllers): the
  paired ratio (each controller / the first) against each axis, and its distribution;
* ``logs/<run_id>.mcap`` with ``--logs`` (about 1.8 MB and +50 % run time per 40 s run).

Metrics of a diverged run cover the time until it stopped; they are in the table but left out
of the distributions and ratios (the figures mark failed runs with crosses).

Resume: ``run_id`` is ``s<sample>-<controller>``; ``key`` is a hash of the run's resolved
scenario (every parameter, the controller and the seed). A rerun with the same arguments skips
every run whose key is in ``runs.jsonl`` (whatever its status, except ``crashed``: a worker
process that died is retried). A different definition (scenario content, specs, ``--n``,
``--seed``, controllers) in the same DIR is refused with what differs; ``fresh=True``
(``--fresh``) deletes the old results first. ``workers``, ``engine`` and ``logs`` may change.

Failures: a run that diverges is recorded with status ``diverged`` and its reason; one that
finishes with a joint more than 1 deg past the plant's range, with ``joint_limit`` (counted as
failed, shown apart in the summary's status counts; its metrics are complete); one that
raises, with ``error`` and the exception; a worker process that dies (e.g. a crash in native
code) is retried up to twice in a fresh pool, then recorded as ``crashed``. None stops the
sweep.

Engines: ``process`` (default): a local ``ProcessPoolExecutor`` with the ``spawn`` start
method (no fork of a process holding MuJoCo state and ctypes callbacks); ``ray``: Ray tasks
(``pip install 'uvms-mj[ray]'``; imported only then; uses the cluster of ``RAY_ADDRESS`` if
set or an already initialised Ray, else starts a local one with ``workers`` CPUs); ``serial``:
in this process (debugging). Each run builds its own plant; the native hydrodynamics are
compiled once into the cache before the workers start.
"""

from __future__ import annotations

# spec: the SPEC language; plan: keys, samples, runs; engines: where runs execute; runner: resume
# and the run loop; table, summary, figures: the outputs.
# (The names not in __all__ are public too: the SPEC classes and limits, the plan's parts, the engines.)
from uvms_mj.analysis.sweep.engines import ENGINES, MAX_ATTEMPTS, RAY_MISSING, check_engine, execute_run  # noqa: F401
from uvms_mj.analysis.sweep.figures import plot_sweep
from uvms_mj.analysis.sweep.plan import (FORMAT, MAX_RUNS, Assignment, Axis, Run, SweepPlan, Vary,  # noqa: F401
                                         check_controllers, parse_vary, plan_sweep, run_seed, sample_count,
                                         sample_parameters)
from uvms_mj.analysis.sweep.runner import FINISHED, SweepOutcome, prepare_out, run_sweep  # noqa: F401
from uvms_mj.analysis.sweep.spec import (MAX_GRID, SPEC_HELP, Grid, Random, Scale, Spec, SweepError,  # noqa: F401
                                         Vector, parse_spec)
from uvms_mj.analysis.sweep.summary import SUMMARY_METRICS, format_summary, summarize  # noqa: F401
from uvms_mj.analysis.sweep.table import METRICS, read_results  # noqa: F401

__all__ = [
    "RAY_MISSING",
    "SweepError",
    "SweepOutcome",
    "SweepPlan",
    "format_summary",
    "parse_spec",
    "parse_vary",
    "plan_sweep",
    "plot_sweep",
    "read_results",
    "run_sweep",
    "sample_parameters",
    "summarize",
]
