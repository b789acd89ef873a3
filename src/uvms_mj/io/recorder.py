"""Record closed-loop runs to MCAP (Foxglove-ready) and read them back.

A log is written incrementally while the run goes (:class:`McapRecorder`, whose
:meth:`~McapRecorder.write_sample` is the loop's ``sink``) and can be read back into an object
that works wherever a :class:`~uvms_mj.sim.loop.RunResult` does (:func:`read_log`), including a log
cut short by ``kill -9`` (it is then read up to the last flush and marked ``truncated``).

Encoding: every channel is JSON (``message_encoding="json"``) with a JSON schema
(``schema_encoding="jsonschema"``), in zstd-compressed chunks. Floats are written with Python's
shortest round-trip repr, so float64 values come back bit for bit; NaN is written as ``null``
and +-inf as ``+-1e999`` (both read back as such by Python and by Foxglove's JSON parser).

Channel layout (times are simulation time: ``log_time = publish_time = round(t * 1e9)`` ns
from the run's start, so Foxglove shows 1970-01-01 00:00:00 + t; the MCAP message ``sequence``
is the sample index k):

=====================  =======================  ==============================================
topic                  schema                   content and rate
=====================  =======================  ==============================================
``/tf``                foxglove.FrameTransforms ``view -> world -> base -> link1 -> link2 ->
                                                tip``: ``world -> ...`` from ``q_true`` and the
                                                robot parameters; ``view -> world`` is a fixed
                                                +90 deg about x, so that with display frame
                                                ``view`` the world's Y-up plane stands upright
                                                in Foxglove's Z-up 3D view (display frame
                                                ``world`` shows it from above). One message per
                                                sample (60 Hz with the paper's T).
``/scene``             foxglove.SceneUpdate     the robot: frame-locked cubes ``base``,
                                                ``link1``, ``link2`` (box sizes and centres from
                                                the parameters), thruster axes, a tip sphere;
                                                once, at the first sample.
``/scene/paths``       foxglove.SceneUpdate     line strips in ``world``: desired tip path
                                                (from ``p_desired[3:5]``, green) and true tip
                                                path (``tip_true``, red), points every
                                                ``path_resolution`` s; the whole path so far,
                                                re-sent every ``path_period`` s of run time and
                                                at close (so seeking in Foxglove always shows it).
``/joint_states``      foxglove.JointStates     ``joints``: one {``name``, ``position`` (q_true),
                                                ``velocity`` (qd_true)} per joint; one per
                                                sample. (Logs written before Foxglove had this
                                                schema used ``uvms_mj.JointStates``, with
                                                ``name``/``position``/``velocity`` arrays;
                                                :func:`read_log` never reads this channel, so
                                                both read back alike.)
``/state/true``        uvms_mj.TrueState        ``t`` and the true plant state ``q_true``,
                                                ``qd_true``, ``tip_true``; one per sample.
``/control``           uvms_mj.ControlSample    ``t`` and every other per-sample signal (the
                                                controller's signals, ``q_measured``, thruster
                                                and torque commands...) as top-level fields;
                                                one per sample.
=====================  =======================  ==============================================

Robot logs (any floating robot: ``McapRecorder(path, None, metadata, model=plant.model)``
with a free vehicle's :class:`~uvms_mj.plant.plant.Plant` model; World z up, so ``view`` is ``world``) have the
same ``/state/true`` and ``/control`` channels and, by the model's own names
(:class:`~uvms_mj.plant.robot.Layout`):

=====================  =======================  ==============================================
topic                  schema                   content and rate
=====================  =======================  ==============================================
``/tf``                foxglove.FrameTransforms the model's kinematic tree: ``view -> world``
                                                (fixed identity, so display frame ``view``
                                                works for every log), then ``<parent> ->
                                                <body>`` for every body (parent = the model's
                                                parent body, ``world`` for the root; the body
                                                frame in its parent's, from ``q_true`` through
                                                ``mj_kinematics``); one message per sample.
``/scene``             foxglove.SceneUpdate     per body a frame-locked entity (id and frame =
                                                the body's name) with its geoms of groups 0-2
                                                (box -> cube, sphere/ellipsoid -> sphere,
                                                cylinder/capsule -> cylinder, mesh -> its
                                                bounding box; planes left out; colour from
                                                ``geom_rgba``), ``thrusters`` (an arrow along
                                                each thruster site's x axis: positive thrust),
                                                ``tip`` (a sphere at the tip site); once, at
                                                the first sample.
``/scene/paths``       foxglove.SceneUpdate     3-D line strips in ``world``: desired tip path
                                                (``tip_desired``, green, when logged), tip path
                                                (``tip_true``, red, when the robot has a tip)
                                                and base path (``q_true[0:3]``, blue); as for
                                                the paper's paths.
``/joint_states``      foxglove.JointStates     the arm joints (Layout.joint_names): position
                                                [rad] from ``q_true``, velocity [rad/s] from
                                                ``qd_true``; one per sample (none for a robot
                                                without joints).
``/thrusters``         uvms_mj.Thrusters        ``t`` and, per thruster actuator name,
                                                ``{"command", "force"}`` [N] (from
                                                ``thrust_command`` / ``thrust_force``); plot
                                                e.g. ``/thrusters.bluerov2_t1.force``. One per
                                                sample.
=====================  =======================  ==============================================

Per-sample signals are plotted in Foxglove's Plot panel with message paths such as
``/control.e_p[3]``, ``/control.det_B`` or ``/state/true.q_true[2]``. Booleans are written as
0/1 integers (so that they plot) and arrays of two or more dimensions are flattened row-major
(Foxglove's JSON-schema parser rejects nested arrays); each sample channel's metadata
(``uvms_mj.signals``) keeps every signal's dtype, shape and position in the row, which
:func:`read_log` uses to give back exactly the loop's arrays (same names, order, shapes and
dtypes). Signals are discovered from
the first row; a name that first appears later is dropped with a warning, and non-numeric values
are not recorded.

Metadata records: ``uvms_mj`` (written at creation) holds the caller's metadata dict plus
``versions`` (uvms_mj, mujoco, numpy, mcap, python), ``git_commit`` / ``git_dirty`` (from git
when the package runs from a checkout, else written into the wheel when it was built, else
``git_commit`` = "unknown"), ``robot_params``, ``created_utc`` and ``log_format``;
``uvms_mj.status`` (written at close) holds ``status`` ("ok", "diverged", "interrupted",
"error"...), ``reason`` and any run metadata given to :meth:`McapRecorder.close`. Each value
is stored as JSON text (MCAP metadata is string -> string).

Durability: data reaches the file at least every ``flush_interval`` seconds of wall-clock time
while samples arrive (checked at each sample, and always after the first one: the samples since
the last flush are encoded and written, the chunk in progress is finished and the file object
flushed), so a process killed with ``kill -9`` leaves a log readable (by :func:`read_log`, not
by MCAP's indexed readers) up to the last flush. Exceptions, KeyboardInterrupt and (inside
:func:`handle_sigterm`) SIGTERM close the log cleanly with a status record.

Writer process (``writer="auto"``, the default on Linux with 2 or more cores, a flush interval
above 0, no live sink, outside a pool's worker; :mod:`uvms_mj.io.writer_process`): after the first
sample the recorder forks, and the child -- a copy of the recorder -- encodes, compresses and
writes the samples with the same code (the same messages, byte for byte:
``tests/test_writer_process.py``). The simulation's process keeps a shallow copy of each row
and every 256 samples packs them column by column (an array signal stacked into one block) and
sends them down a pipe: about 0.02 ms per sample instead of the encoding's 0.07-0.2 ms. The
flushes are the same (the child flushes when this process's clock says so; :meth:`flush` waits
for it); ``kill -9`` of the simulation's process ends the child at the end of its pipe and leaves
the log truncated at the last flush; the child ignores SIGINT (the owner closes the log); its
exceptions (a full disk...) are raised here, by a later ``write_sample`` or by ``close``, with the
child's traceback as a note; ``close`` waits for the child and reaps it; a child that died is a
RuntimeError, never a hang. ``writer="inline"`` (or ``UVMS_MJ_LOG_WRITER=inline``) writes in
this process.

Speed: the samples are encoded in batches at each flush (in the writer process: at each batch;
per batch one orjson call for the sample channels and one for the paper's /tf and /joint_states
numbers, whose templates are then filled for the whole batch in one operation each; the same
bytes as one sample at a time, which irregular rows -- a non-finite number, a missing or late
signal -- still take), added to the chunk in one call per batch, and compressed by one reused
zstd compressor at level 1 (:class:`uvms_mj.io.mcap_writer.LeanWriter`). A row is kept (a
shallow copy) until its batch is written: its arrays must not be changed in place after
:meth:`McapRecorder.write_sample`.

Live view: given ``live=`` (:class:`uvms_mj.io.live.LiveServer`, ``uvms-mj run --live``), the recorder
writes the same channels and messages through :class:`uvms_mj.io.sinks.Tee` to the file and to the
Foxglove WebSocket server, encodes its pending samples every ``push_interval`` s of wall time and lets
the server pace the run (real time or as fast as possible).

Typical use (e.g. in the CLI)::

    with handle_sigterm(), McapRecorder(path, plant.params, metadata) as rec:
        result = run_closed_loop(plant, ctrl, duration, sink=rec.write_sample)
        rec.close(result.status, result.reason, meta=result.meta)
    log = read_log(path)      # log.t, log.signals, log.status, log.meta, log.truncated
"""

from __future__ import annotations

# The layout above is written and read by the modules below (one responsibility each); this
# module gathers their public names, so that ``from uvms_mj.io.recorder import ...`` keeps working.
from uvms_mj.io.interrupts import Terminated, handle_sigterm
from uvms_mj.io.paths import LogInUseError, OutputPathError, check_output_dir, check_output_path  # noqa: F401
from uvms_mj.io.provenance import provenance
from uvms_mj.io.reader import LogData, format_info, iter_messages, log_info, read_log
from uvms_mj.io.robot_channels import geom_primitive  # noqa: F401
from uvms_mj.io.schemas import (LEGACY_JOINT_STATES, LOG_FORMAT, METADATA_NAME, RESERVED_KEYS, SAMPLE_TOPICS,  # noqa: F401
                                SCHEMAS, STATE_SIGNALS, STATUS_NAME, TOPIC_CONTROL, TOPIC_JOINTS, TOPIC_PATHS,
                                TOPIC_SCENE, TOPIC_STATE, TOPIC_TF, TOPIC_THRUSTERS)
from uvms_mj.io.writer import McapRecorder

__all__ = [
    "LOG_FORMAT",
    "LogData",
    "McapRecorder",
    "Terminated",
    "format_info",
    "handle_sigterm",
    "iter_messages",
    "log_info",
    "provenance",
    "read_log",
]
