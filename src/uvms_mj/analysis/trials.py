"""Reading recorded pool trials (the Hinsdale 2023 format) into SI arrays.

A trial folder holds, per trial ``<name>`` (e.g. ``003-0``, ``baseline1``, ``alt_001-0``):

* ``traj<name>_imu.csv`` or ``<name>_imu.csv`` (required), columns ``time_secs, x_ori, y_ori,
  z_ori, w_ori`` (orientation quaternion, scalar last, vehicle frame x forward, y left, z up, in
  a world frame with z up) and optionally ``x_angvel .. z_angvel`` [rad/s], ``x_linacc ..
  z_linacc`` [m/s^2]. The files carry no roll/pitch columns: :class:`ImuData` derives them from
  the quaternion (Z-Y-X Euler angles, the same as from the "up" vector, see
  :func:`roll_pitch_yaw`).
* ``..._joint_states.csv`` (required), columns ``time_secs, axis_a_pos .. axis_e_pos, axis_a_vel
  .. axis_e_vel`` [rad, rad/s]; axis_a = jaw (fixed), b = wrist, c = elbow, d = shoulder,
  e = base.
* ``..._mocap.csv`` (optional), ``time_secs, x_pose, y_pose, z_pose`` [m], ``x_ori .. w_ori``,
  ``roll, pitch, yaw`` [rad]; further columns are ignored.
* ``metadata_<name>.yml`` (optional; the baselines have none): ``start_time`` [s], the start of
  the planned arm motion on the trial clock.

All files share one clock, ``time_secs``. The leading ``traj`` of the CSV names and a leading
``_`` of the key (``traj_alt_001-0`` / ``metadata__alt_001-0``) are dropped from the trial name.

Joint states: the rows arrive at about 55 Hz but the positions update at about 21 Hz, so most
rows repeat the previous one. :class:`JointData` keeps the *first* row of each run of rows whose
ten values (five positions, five velocities) are all equal to the row before: its time is the
earliest time the new value was seen (the best estimate of the update time). A genuine update
that happens to repeat every value exactly is dropped too; interpolating across it is then off
by at most one update step (~0.05 s of motion). (In the Hinsdale files the five axes update
together in ~21 Hz messages; per axis ~10 % of the messages repeat the position with a new
velocity, and during motion single readings jump by up to ~0.15 rad and back, e.g. axis_b of
traj_alt_011-0_joint_states.csv line 474: the low-pass of :meth:`JointData.smoothed` is meant
for those.) Recorded axes are mapped to model joint angles
by ``q = axis - offset`` with the offsets of the model's ``<numeric
name="hinsdale:joint_offsets">`` (order base, shoulder, elbow, wrist = axis_e, axis_d, axis_c,
axis_b); the jaw (axis_a) is kept only as a raw axis.

Bad data is reported, not raised: :func:`load_trials` returns every problem as a
:class:`TrialIssue` (trial, file, line number, message, severity). An ``"error"`` in a required
file (IMU, joint states, metadata) skips that trial (it is named in ``TrialSet.skipped``); the
others still load. Problems in the optional mocap are ``"warning"``: gaps (mocap is known to
have them) keep the mocap, NaN / unparsable / unsorted mocap rows drop the mocap (``None``).
Checks per CSV: the file exists, the header has the required columns, every field parses as a
finite number (an empty field, ``nan`` or ``inf`` is a "NaN row"), time strictly increases (a
repeated or decreasing time is reported at its line), and no two consecutive rows are more than
``max_gap`` seconds apart. Line numbers are 1-based file lines (the header is line 1).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

from uvms_mj.io.paths import LineTooLong, read_lines

__all__ = [
    "DEFAULT_CUTOFF_HZ",
    "DEFAULT_MAX_GAP_S",
    "JOINT_AXES",
    "JOINT_NAMES",
    "ImuData",
    "JointData",
    "MocapData",
    "Trial",
    "TrialIssue",
    "TrialSet",
    "joint_offsets",
    "load_trial",
    "load_trials",
    "lowpass",
    "roll_pitch_yaw",
    "uniform_grid",
]
# One module of about 600 lines (a sixth of them the format's description above): the data classes,
# the row checks and the loader describe one file format together; split, each part would need the others.

#: Model joints and the recorded axis each comes from (the order of the model's offsets).
JOINT_NAMES: tuple[str, ...] = ("alpha_base", "alpha_shoulder", "alpha_elbow", "alpha_wrist")
JOINT_AXES: tuple[str, ...] = ("axis_e", "axis_d", "axis_c", "axis_b")
#: All recorded axes, in file order (axis_a = jaw, fixed in the trials).
ALL_AXES: tuple[str, ...] = ("axis_a", "axis_b", "axis_c", "axis_d", "axis_e")
OFFSETS_NUMERIC = "hinsdale:joint_offsets"

#: Default low-pass cutoff of :meth:`JointData.smoothed` [Hz]. The positions update at about
#: 21 Hz (Nyquist ~10.5 Hz), so the stair steps and the +-1 update timing jitter of the stream
#: sit at and above ~5-10 Hz; the planned motions are slow (each leg takes ~10-20 s; their
#: spectrum is below ~0.5 Hz) and the vehicle rings at ~0.38 Hz (period 2.6 s). 2 Hz passes
#: all the motion (and its first derivatives) unchanged and is a factor of ~5 below the update
#: Nyquist frequency.
DEFAULT_CUTOFF_HZ = 2.0
#: Default Butterworth order (filtfilt doubles it: 4th-order magnitude, zero phase).
DEFAULT_FILTER_ORDER = 2
#: Largest allowed time between consecutive rows [s] (IMU ~0.05 s nominal, joint rows ~0.02 s,
#: the largest seen in the Hinsdale IMU / joint files is 0.2 s).
DEFAULT_MAX_GAP_S = 0.5

IMU_REQUIRED = ("time_secs", "x_ori", "y_ori", "z_ori", "w_ori")
IMU_OPTIONAL = ("x_angvel", "y_angvel", "z_angvel", "x_linacc", "y_linacc", "z_linacc")
JOINT_REQUIRED = ("time_secs",) + tuple(f"{a}_pos" for a in ALL_AXES) + tuple(f"{a}_vel" for a in ALL_AXES)
MOCAP_REQUIRED = ("time_secs", "x_pose", "y_pose", "z_pose", "x_ori", "y_ori", "z_ori", "w_ori",
                  "roll", "pitch", "yaw")


# ------------------------------------------------------------------------------- data classes


@dataclass(frozen=True)
class TrialIssue:
    """One problem found while reading a trial.

    Attributes:
        trial: the trial's name.
        file: the file concerned (None: the trial as a whole).
        line: 1-based line in that file (1 = header), or None for the whole file.
        message: what is wrong.
        severity: ``"error"`` (the trial is skipped) or ``"warning"`` (the trial is kept).
    """

    trial: str
    file: Path | None
    line: int | None
    message: str
    severity: str = "error"

    def __str__(self) -> str:
        where = "" if self.file is None else self.file.name + ("" if self.line is None else f":{self.line}")
        return f"{self.severity}: trial {self.trial}: {where + ': ' if where else ''}{self.message}"


@dataclass
class ImuData:
    """IMU samples (as recorded; ~20 Hz).

    Attributes:
        t: (N,) time [s], strictly increasing.
        quat: (N, 4) orientation quaternion x, y, z, w (as recorded, scalar last; vehicle FLU
            to a world frame with z up).
        roll, pitch, yaw: (N,) Z-Y-X Euler angles of ``quat`` [rad] (yaw drifts; roll > 0:
            right side down, pitch > 0: nose down, as the model's convention).
        ang_vel: (N, 3) angular velocity [rad/s] or None; lin_acc: (N, 3) [m/s^2] or None.
        lines: (N,) file line of each sample.
    """

    t: np.ndarray
    quat: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    yaw: np.ndarray
    ang_vel: np.ndarray | None = None
    lin_acc: np.ndarray | None = None
    lines: np.ndarray | None = None

    def window_mean(self, t0: float, t1: float) -> tuple[float, float, int]:
        """Mean roll, pitch [rad] over ``t0 <= t < t1`` and the number of samples used."""
        sel = (self.t >= t0) & (self.t < t1)
        n = int(sel.sum())
        if n == 0:
            return math.nan, math.nan, 0
        return float(self.roll[sel].mean()), float(self.pitch[sel].mean()), n


@dataclass
class MocapData:
    """Motion-capture samples (~100 Hz, irregular, gaps; world z up).

    Attributes:
        t: (N,) time [s]; pos: (N, 3) [m]; quat: (N, 4) x, y, z, w; roll, pitch, yaw: (N,)
        [rad] as recorded (Z-Y-X Euler); lines: (N,) file lines.
    """

    t: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    yaw: np.ndarray
    lines: np.ndarray | None = None


@dataclass
class JointData:
    """Arm joint states, de-duplicated (one sample per position update, ~21 Hz).

    Attributes:
        t: (N,) update times [s] (first row of each run of repeated rows).
        axes_pos, axes_vel: (N, 5) recorded axis_a..axis_e positions [rad] / velocities [rad/s].
        q, qd: (N, 4) model joint angles [rad] / rates [rad/s], order :data:`JOINT_NAMES`
            (``q = axis - offset``; ``qd`` = the recorded axis velocities).
        offsets: (4,) the offsets used [rad].
        names: the model joint names (columns of ``q``).
        lines: (N,) file line of each kept row.
        n_rows: the number of data rows in the file (before de-duplication).
    """

    t: np.ndarray
    axes_pos: np.ndarray
    axes_vel: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    offsets: np.ndarray
    names: tuple[str, ...] = JOINT_NAMES
    lines: np.ndarray | None = None
    n_rows: int = 0

    @property
    def update_rate(self) -> float:
        """Mean position update rate [Hz] of the kept rows."""
        return (len(self.t) - 1) / (self.t[-1] - self.t[0]) if len(self.t) > 1 else math.nan

    def at(self, t: float | np.ndarray) -> np.ndarray:
        """Joint angles at time(s) ``t`` [rad] by linear interpolation (held at the ends)."""
        tt = np.atleast_1d(np.asarray(t, float))
        out = np.column_stack([np.interp(tt, self.t, self.q[:, j]) for j in range(self.q.shape[1])])
        return out[0] if np.ndim(t) == 0 else out

    def resampled(self, dt: float = 0.01, t0: float | None = None, t1: float | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Joint angles on a uniform grid by linear interpolation between the updates.

        Args:
            dt: grid step [s] (default 0.01 s = 100 Hz).
            t0, t1: grid span (default and bounds: the first and last update; no extrapolation).

        Returns:
            ``(t, q)``: (M,) grid times and (M, 4) joint angles.
        """
        t = uniform_grid(self.t[0] if t0 is None else max(t0, self.t[0]),
                         self.t[-1] if t1 is None else min(t1, self.t[-1]), dt)
        return t, self.at(t)

    def smoothed(self, dt: float = 0.01, cutoff_hz: float = DEFAULT_CUTOFF_HZ,
                 order: int = DEFAULT_FILTER_ORDER) -> tuple[np.ndarray, np.ndarray]:
        """Joint angles resampled (:meth:`resampled`) and low-pass filtered (:func:`lowpass`:
        zero-phase Butterworth, ``cutoff_hz``, see :data:`DEFAULT_CUTOFF_HZ`).

        Returns:
            ``(t, q)`` on the uniform grid of step ``dt``.
        """
        t, q = self.resampled(dt)
        return t, lowpass(q, dt, cutoff_hz, order)


@dataclass
class Trial:
    """One recorded trial.

    Attributes:
        name: trial name (file stem without ``traj`` / the suffix, e.g. ``003-0``).
        imu, joints: the required streams; mocap: optional (None if absent or unusable).
        start_time: start of the planned motion [s] (``metadata_<name>.yml``), None if unknown
            (the baselines: arm still).
        files: role (``imu``, ``joints``, ``mocap``, ``metadata``) -> path of the files found.
        issues: the warnings of this trial (errors skip a trial).
    """

    name: str
    imu: ImuData
    joints: JointData
    mocap: MocapData | None = None
    start_time: float | None = None
    files: dict = field(default_factory=dict)
    issues: list = field(default_factory=list)

    @property
    def t_end(self) -> float:
        """End of the trial [s]: the last IMU or joint sample, whichever is earlier."""
        return float(min(self.imu.t[-1], self.joints.t[-1]))


@dataclass
class TrialSet:
    """Result of :func:`load_trials`.

    Attributes:
        trials: name -> :class:`Trial` (the trials that loaded), sorted by name.
        skipped: name -> the errors that skipped that trial.
        issues: every issue found (errors and warnings), in reading order.
    """

    trials: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)
    issues: list = field(default_factory=list)

    def __getitem__(self, name: str) -> Trial:
        return self.trials[name]

    def __iter__(self):
        return iter(self.trials.values())

    def __len__(self) -> int:
        return len(self.trials)

    def report(self) -> str:
        """One line per issue, then the skipped trials."""
        lines = [str(i) for i in self.issues]
        if self.skipped:
            lines.append("skipped: " + ", ".join(sorted(self.skipped)))
        return "\n".join(lines)


# ------------------------------------------------------------------------------- helpers


def uniform_grid(t0: float, t1: float, dt: float) -> np.ndarray:
    """``t0, t0 + dt, ...`` up to ``t1`` (inclusive within 1e-9 dt)."""
    if not dt > 0:
        raise ValueError(f"dt must be > 0, got {dt}")
    n = int(math.floor((t1 - t0) / dt + 1e-9)) + 1
    return t0 + dt * np.arange(max(n, 0))


def lowpass(x: np.ndarray, dt: float, cutoff_hz: float = DEFAULT_CUTOFF_HZ,
            order: int = DEFAULT_FILTER_ORDER) -> np.ndarray:
    """Zero-phase low-pass of uniformly sampled data along axis 0.

    ``scipy.signal.filtfilt`` with a Butterworth filter of ``order`` and cutoff ``cutoff_hz``
    (run forward and backward: no delay, magnitude squared, -6 dB at the cutoff), odd
    extension at the ends ("pad" method, default length).

    Raises:
        ValueError: cutoff not below the Nyquist frequency 1 / (2 dt), or too few samples.
    """
    from scipy.signal import butter, filtfilt

    nyq = 0.5 / dt
    if not 0 < cutoff_hz < nyq:
        raise ValueError(f"cutoff {cutoff_hz} Hz must lie in (0, {nyq}) Hz for dt = {dt} s")
    b, a = butter(order, cutoff_hz / nyq)
    return filtfilt(b, a, np.asarray(x, float), axis=0)


def roll_pitch_yaw(quat_xyzw: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Z-Y-X Euler angles (roll, pitch, yaw) [rad] of quaternions given x, y, z, w.

    Roll and pitch are those of the world "up" axis seen in the vehicle frame,
    ``u = R^T e_z``: roll = atan2(u_y, u_z), pitch = asin(-u_x) (the model's convention). The
    sign of the quaternion does not matter.
    """
    q = np.asarray(quat_xyzw, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    # third row of the rotation matrix (vehicle -> world): world z in vehicle axes
    ux = 2 * (x * z - w * y)
    uy = 2 * (y * z + w * x)
    uz = 1 - 2 * (x * x + y * y)
    roll = np.arctan2(uy, uz)
    pitch = np.arcsin(np.clip(-ux, -1.0, 1.0))
    yaw = np.arctan2(2 * (x * y + w * z), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def joint_offsets(model=None) -> np.ndarray:
    """The joint offsets (base, shoulder, elbow, wrist) [rad] of ``<numeric
    name="hinsdale:joint_offsets">`` in a compiled model (default: ``models/hinsdale2023/hinsdale2023.xml``).

    Raises:
        KeyError: the model has no such numeric; ValueError: it has not 4 values.
    """
    if model is None:
        from uvms_mj.physics import load_model
        from uvms_mj.plant.plant import models_dir

        model = load_model(models_dir() / "hinsdale2023" / "hinsdale2023.xml")
    try:
        data = np.array(model.numeric(OFFSETS_NUMERIC).data, float)
    except KeyError as e:
        raise KeyError(f"the model has no <numeric name={OFFSETS_NUMERIC!r}>") from e
    if data.shape != (4,):
        raise ValueError(f"{OFFSETS_NUMERIC} must hold 4 values (base shoulder elbow wrist), got {data}")
    return data


#: The longest line of a trial CSV [characters] (ours: the longest row of the Hinsdale 2023 trials is 284
#: characters; a longer line, e.g. 200 MB without a line end, is refused without being read whole).
CSV_LINE_MAX = 10_000
#: The largest magnitude of a trial CSV value (ours: the times are seconds since 1970, 1.7e9; 1e308 as a
#: quaternion component overflowed its norm).
VALUE_MAX = 1e12


class _Reader:
    """Collects the issues of one trial."""

    def __init__(self, trial: str, issues: list):
        self.trial, self.issues = trial, issues

    def add(self, file, line, message, severity="error") -> None:
        self.issues.append(TrialIssue(self.trial, file, line, message, severity))

    def csv(self, path: Path | None, required: Sequence[str], optional: Sequence[str] = (),
            severity: str = "error", max_gap: float = DEFAULT_MAX_GAP_S,
            gap_severity: str | None = None) -> tuple[dict, np.ndarray] | None:
        """Parse a numeric CSV: column -> (N,) array for the required and the optional columns
        present, and the (N,) file line of each row; None (with issues) if unusable."""
        gap_severity = gap_severity or severity
        if path is None or not path.exists():
            self.add(path, None, "file missing", severity)
            return None
        if not path.is_file():  # a folder, a FIFO or a device (/dev/zero): reading would block or never end
            self.add(path, None, "not a regular file (a folder, FIFO or device): not read", severity)
            return None
        try:
            text, ended = read_lines(path, CSV_LINE_MAX)
        except LineTooLong as e:
            self.add(path, e.line, f"longer than {CSV_LINE_MAX} characters: not a CSV row (the file is not read "
                     "further)", severity)
            return None
        except UnicodeDecodeError as e:
            self.add(path, None, f"not UTF-8 text (byte {e.start}: {e.reason})", severity)
            return None
        except OSError as e:
            self.add(path, None, f"unreadable: {e.strerror or e}", severity)
            return None
        if text and not ended:
            # a file cut while it was written (its last field may be cut short too)
            self.add(path, len(text), "the last line has no line end: the file may be cut short there", "warning")
        if not text or not text[0].strip():
            self.add(path, 1, "empty file (no header)", severity)
            return None
        header = [h.strip() for h in text[0].split(",")]
        missing = [c for c in required if c not in header]
        if missing:
            self.add(path, 1, f"missing column(s) {', '.join(missing)}", severity)
            return None
        cols = [c for c in (*required, *optional) if c in header]
        idx = [header.index(c) for c in cols]
        rows, lines, bad = [], [], False
        for ln, raw in enumerate(text[1:], start=2):
            if not raw.strip():
                continue  # a blank line (e.g. at the end) carries nothing
            parts = raw.split(",")
            if len(parts) != len(header):
                self.add(path, ln, f"{len(parts)} fields, header has {len(header)}", severity)
                bad = True
                continue
            try:
                vals = [float(parts[i]) for i in idx]
            except ValueError:
                self.add(path, ln, "unparsable field", severity)
                bad = True
                continue
            nonfinite = [c for c, v in zip(cols, vals) if not math.isfinite(v)]
            if nonfinite:
                self.add(path, ln, f"NaN/inf in {', '.join(nonfinite)}", severity)
                bad = True
                continue
            huge = [c for c, v in zip(cols, vals) if abs(v) > VALUE_MAX]
            if huge:
                self.add(path, ln, f"|value| > {VALUE_MAX:g} in {', '.join(huge)}", severity)
                bad = True
                continue
            rows.append(vals)
            lines.append(ln)
        if len(rows) < 2:  # a time series needs two samples (rates, interpolation)
            self.add(path, None, "no data rows" if not rows else "one data row: at least 2 are needed", severity)
            return None
        a = np.array(rows)
        lines_a = np.array(lines)
        t = a[:, 0]
        dt = np.diff(t)
        for k in np.flatnonzero(dt <= 0):
            what = "repeated time" if dt[k] == 0 else "time goes backwards"
            self.add(path, int(lines_a[k + 1]), f"{what}: {t[k + 1]:.6f} s after {t[k]:.6f} s (line {lines_a[k]})", severity)
            bad = True
        for k in np.flatnonzero(dt > max_gap):
            self.add(path, int(lines_a[k + 1]),
                     f"gap of {dt[k]:.3f} s (> {max_gap} s) after line {lines_a[k]} (t = {t[k]:.3f} s)", gap_severity)
            bad = bad or gap_severity == "error"
        if bad:
            return None
        return {c: a[:, i] for i, c in enumerate(cols)}, lines_a


# ------------------------------------------------------------------------------- loading


_CSV = re.compile(r"^(?:traj)?(?P<key>.+?)_(?P<role>imu|joint_states|mocap)\.csv$")
_META = re.compile(r"^metadata_(?P<key>.+)\.ya?ml$")
_ROLE = {"imu": "imu", "joint_states": "joints", "mocap": "mocap"}
_FILE_PATTERN = {"imu": "{}_imu.csv", "joints": "{}_joint_states.csv", "mocap": "{}_mocap.csv"}


def _trial_name(key: str) -> str:
    return key.lstrip("_") or key


def _prefix(files: Mapping[str, Path], name: str) -> str:
    """The CSV stem prefix of a trial (``traj003-0``, ``baseline1``) from its other files."""
    for p in files.values():
        m = _CSV.match(p.name)
        if m:
            return p.name[: m.start("role") - 1]
    meta = files.get("metadata")
    return "traj" + (_META.match(meta.name)["key"] if meta is not None else name)


def _discover(folder: Path) -> dict[str, dict[str, Path]]:
    found: dict[str, dict[str, Path]] = {}
    for p in sorted(folder.iterdir()):
        if not p.is_file():
            continue
        m = _CSV.match(p.name)
        if m:
            found.setdefault(_trial_name(m["key"]), {})[_ROLE[m["role"]]] = p
            continue
        m = _META.match(p.name)
        if m:
            found.setdefault(_trial_name(m["key"]), {})["metadata"] = p
    return found


#: The largest trial metadata file [bytes] (ours: the Hinsdale 2023 ones are below 1 kB).
METADATA_MAX = 1_000_000


def _read_start_time(r: _Reader, path: Path) -> tuple[float | None, bool]:
    """(start_time, ok) from a metadata YAML file."""
    import yaml

    if not path.is_file():  # a FIFO or a device: reading would block or never end
        r.add(path, None, "not a regular file (a folder, FIFO or device): not read")
        return None, False
    try:
        if path.stat().st_size > METADATA_MAX:
            raise OSError(f"{path.stat().st_size} bytes; a metadata file is at most {METADATA_MAX} bytes")
        text = path.read_text(encoding="utf-8")
        doc = yaml.safe_load(text)
    except UnicodeDecodeError as e:
        r.add(path, None, f"not UTF-8 text (byte {e.start}: {e.reason})")
        return None, False
    except (OSError, yaml.YAMLError) as e:
        line = getattr(getattr(e, "problem_mark", None), "line", None)
        r.add(path, None if line is None else line + 1, f"unreadable YAML: {' '.join(str(e).split())}")
        return None, False
    line = next((i for i, s in enumerate(text.splitlines(), 1) if s.strip().startswith("start_time")), None)
    if not isinstance(doc, dict) or "start_time" not in doc:
        r.add(path, None, "no start_time")
        return None, False
    v = doc["start_time"]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        r.add(path, line, f"start_time must be a finite number [s], got {v!r}")
        return None, False
    if v < 0:  # only the static check uses it: the trial is kept, its start unknown
        r.add(path, line, f"start_time {v!r} s < 0: ignored (start of the motion unknown)", "warning")
        return None, True
    return float(v), True


def load_trial(name: str, files: Mapping[str, Path], offsets: np.ndarray,
               max_gap: float = DEFAULT_MAX_GAP_S, issues: list | None = None) -> Trial | None:
    """Read one trial from its files (role -> path: ``imu``, ``joints``, optional ``mocap``,
    ``metadata``). Issues are appended to ``issues``; returns None on any error."""
    issues = [] if issues is None else issues
    n0 = len(issues)
    r = _Reader(name, issues)
    offsets = np.asarray(offsets, float)

    imu_r = r.csv(files.get("imu"), IMU_REQUIRED, IMU_OPTIONAL, max_gap=max_gap)
    js_r = r.csv(files.get("joints"), JOINT_REQUIRED, max_gap=max_gap)
    mc_r = None
    if "mocap" in files:
        mc_r = r.csv(files["mocap"], MOCAP_REQUIRED, severity="warning", max_gap=max_gap)
        if mc_r is None:
            r.add(files["mocap"], None, "mocap not used", "warning")
    start_time, meta_ok = None, True
    if "metadata" in files:
        start_time, meta_ok = _read_start_time(r, files["metadata"])
    else:
        r.add(None, None, "no metadata file: start time of the motion unknown", "warning")

    if imu_r is None or js_r is None or not meta_ok:
        return None

    c, lines = imu_r
    quat = np.column_stack([c[k] for k in ("x_ori", "y_ori", "z_ori", "w_ori")])
    norm = np.linalg.norm(quat, axis=1)
    bad_q = np.flatnonzero(np.abs(norm - 1) > 1e-3)
    for k in bad_q[:5]:
        r.add(files["imu"], int(lines[k]), f"quaternion norm {norm[k]:.6f} (not unit)")
    if len(bad_q):
        return None
    roll, pitch, yaw = roll_pitch_yaw(quat)
    has = lambda ks: all(k in c for k in ks)  # noqa: E731
    imu = ImuData(
        t=c["time_secs"], quat=quat, roll=roll, pitch=pitch, yaw=yaw,
        ang_vel=np.column_stack([c[k] for k in IMU_OPTIONAL[:3]]) if has(IMU_OPTIONAL[:3]) else None,
        lin_acc=np.column_stack([c[k] for k in IMU_OPTIONAL[3:]]) if has(IMU_OPTIONAL[3:]) else None,
        lines=lines,
    )

    c, lines = js_r
    pos = np.column_stack([c[f"{a}_pos"] for a in ALL_AXES])
    vel = np.column_stack([c[f"{a}_vel"] for a in ALL_AXES])
    allv = np.hstack([pos, vel])
    keep = np.r_[True, np.any(allv[1:] != allv[:-1], axis=1)]
    pos, vel = pos[keep], vel[keep]
    jcols = [ALL_AXES.index(a) for a in JOINT_AXES]
    joints = JointData(
        t=c["time_secs"][keep], axes_pos=pos, axes_vel=vel, q=pos[:, jcols] - offsets,
        qd=vel[:, jcols].copy(), offsets=offsets.copy(), lines=lines[keep], n_rows=len(keep),
    )

    mocap = None
    if mc_r is not None:
        c, lines = mc_r
        mocap = MocapData(
            t=c["time_secs"], pos=np.column_stack([c["x_pose"], c["y_pose"], c["z_pose"]]),
            quat=np.column_stack([c[k] for k in ("x_ori", "y_ori", "z_ori", "w_ori")]),
            roll=c["roll"], pitch=c["pitch"], yaw=c["yaw"], lines=lines,
        )

    if len(joints.t) < 2 or min(imu.t[-1], joints.t[-1]) <= max(imu.t[0], joints.t[0]):
        r.add(files["imu"], None, f"the IMU record ({imu.t[0]:.3f}..{imu.t[-1]:.3f} s) and the joint record "
              f"({joints.t[0]:.3f}..{joints.t[-1]:.3f} s) do not overlap (one clock, time_secs)")
        return None
    if abs(imu.t[-1] - joints.t[-1]) > 1.0 or abs(imu.t[0] - joints.t[0]) > 1.0:
        # ours: 1 s, several samples of either record (IMU 20 Hz, joints ~21 Hz)
        r.add(files["imu"], None, f"the IMU record ({imu.t[0]:.3f}..{imu.t[-1]:.3f} s) and the joint record "
              f"({joints.t[0]:.3f}..{joints.t[-1]:.3f} s) differ by more than 1 s at an end: the trial is used over "
              "their overlap only", "warning")
    if start_time is not None and not imu.t[0] < start_time < imu.t[-1]:
        r.add(files["metadata"], None,
              f"start_time {start_time} s outside the IMU record {imu.t[0]:.3f}..{imu.t[-1]:.3f} s", "warning")
    return Trial(name=name, imu=imu, joints=joints, mocap=mocap, start_time=start_time,
                 files=dict(files), issues=list(issues[n0:]))


def load_trials(folder: str | Path, model=None, offsets: Iterable[float] | None = None,
                names: Iterable[str] | None = None, max_gap: float = DEFAULT_MAX_GAP_S) -> TrialSet:
    """Read every trial of a folder (see the module docstring for the format and the checks).

    Args:
        folder: the trials folder.
        model: compiled model whose ``hinsdale:joint_offsets`` numeric maps axes to joint angles
            (default: ``models/hinsdale2023/hinsdale2023.xml``); ignored if ``offsets`` is given.
        offsets: the 4 offsets (base, shoulder, elbow, wrist) [rad] directly.
        names: read only these trials (a name with no files at all is reported and skipped).
        max_gap: largest allowed time between consecutive rows of a file [s].

    Returns:
        A :class:`TrialSet`: the trials that loaded, the skipped ones with their errors, and
        every issue.

    Raises:
        FileNotFoundError: ``folder`` is not a folder.
    """
    folder = Path(folder)
    if folder.is_file():
        raise FileNotFoundError(f"trials folder {str(folder)!r} is a file: give the folder that holds the "
                                "trials' CSV files")
    if not folder.is_dir():
        raise FileNotFoundError(f"trials folder {str(folder)!r} does not exist")
    off = np.asarray(list(offsets), float) if offsets is not None else joint_offsets(model)
    if off.shape != (4,):
        raise ValueError(f"offsets must be 4 values (base shoulder elbow wrist), got {off}")
    found = _discover(folder)
    wanted = sorted(found) if names is None else list(names)
    out = TrialSet()
    for name in wanted:
        files = found.get(name)
        if files is None:
            out.issues.append(TrialIssue(name, None, None, f"no files for trial {name!r} in {folder}"))
            out.skipped[name] = [out.issues[-1]]
            continue
        for role in ("imu", "joints"):
            if role not in files:  # name the expected file, so that the report can say which
                files = {**files, role: folder / _FILE_PATTERN[role].format(_prefix(files, name))}
        n0 = len(out.issues)
        trial = load_trial(name, files, off, max_gap, out.issues)
        if trial is None:
            out.skipped[name] = [i for i in out.issues[n0:] if i.severity == "error"]
        else:
            out.trials[name] = trial
    return out
