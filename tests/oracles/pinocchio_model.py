"""The MJCF robot in Pinocchio: an independent truth for rigid-body dynamics and Jacobians.

The model is built by Pinocchio's own MJCF parser (``pinocchio.buildModelFromMJCF``: it reads
the kinematic tree, joint axes, body poses and the explicit ``<inertial>`` elements; it ignores
geom masses, which is why the test models give every body an ``<inertial>``), from the file with
the uvms plugins stripped (Pinocchio does not know them).

Coordinates differ from MuJoCo's for the free joint:

* q:  MuJoCo (x, y, z, qw, qx, qy, qz, joints...) -> Pinocchio (x, y, z, qx, qy, qz, qw, ...);
* v:  MuJoCo (world linear velocity of the body origin, body angular velocity, joints) ->
  Pinocchio (body-frame linear velocity, body angular velocity, joints): v_mj = T v_pin with
  T = blockdiag(R, I); so M_mj = T^-T M_pin T^-1, generalized forces Q_mj = T^-T Q_pin, and a
  Jacobian J_mj = J_pin T^-1;
* accelerations: qacc_mj = 0 is v_dot_pin = (-w x v_body, 0, ...) (d/dt of R^T x_dot).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pinocchio as pin

from . import ref_sim


class PinRobot:
    """Pinocchio model of an MJCF test robot whose root body has a free joint."""

    def __init__(self, xml: str, hydro_frames: dict[str, tuple[np.ndarray, np.ndarray]] | None = None) -> None:
        """Args:
            xml: MJCF text (uvms plugins are stripped here).
            hydro_frames: {body name: (pos, quat w x y z)} frames to add (as OP frames).
        """
        stripped, _, _ = ref_sim.strip_uvms(xml)
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "robot.xml"
            path.write_text(stripped)
            self.model = pin.buildModelFromMJCF(str(path))
        self.data = self.model.createData()
        assert self.model.joints[1].shortname() == "JointModelFreeFlyer"
        self.frames: dict[str, int] = {}
        for body, (pos, quat) in (hydro_frames or {}).items():
            fid = self.model.getFrameId(body, pin.FrameType.BODY)
            parent = self.model.frames[fid]
            w, x, y, z = np.asarray(quat, float) / np.linalg.norm(quat)
            local = pin.SE3(pin.Quaternion(w, x, y, z).toRotationMatrix(), np.asarray(pos, float))
            frame = pin.Frame(f"{body}_hydro", parent.parentJoint, fid, parent.placement * local,
                              pin.FrameType.OP_FRAME)
            self.frames[body] = self.model.addFrame(frame)
        self.data = self.model.createData()

    # --- coordinates
    @staticmethod
    def q_pin(qpos: np.ndarray) -> np.ndarray:
        q = np.array(qpos, float)
        return np.r_[q[:3], q[4:7], q[3], q[7:]]

    def T(self, qpos: np.ndarray) -> np.ndarray:
        """v_mj = T v_pin."""
        w, x, y, z = qpos[3:7]
        R = pin.Quaternion(w, x, y, z).toRotationMatrix()
        T = np.eye(self.model.nv)
        T[:3, :3] = R
        return T

    def v_pin(self, qpos, qvel) -> np.ndarray:
        return np.linalg.solve(self.T(qpos), qvel)

    # --- dynamics in MuJoCo's coordinates
    def mass_matrix(self, qpos) -> np.ndarray:
        M = pin.crba(self.model, self.data, self.q_pin(qpos))
        M = np.triu(M) + np.triu(M, 1).T
        Ti = np.linalg.inv(self.T(qpos))
        return Ti.T @ M @ Ti

    def bias(self, qpos, qvel, gravity) -> np.ndarray:
        """MuJoCo's qfrc_bias (Coriolis, centrifugal, gravity) from Pinocchio's RNEA at qacc = 0."""
        self.model.gravity = pin.Motion(np.asarray(gravity, float), np.zeros(3))
        v = self.v_pin(qpos, qvel)
        a = np.zeros(self.model.nv)
        a[:3] = -np.cross(v[3:6], v[:3])  # d/dt (R^T x_dot) at x_ddot = 0
        tau = pin.rnea(self.model, self.data, self.q_pin(qpos), v, a)
        return np.linalg.inv(self.T(qpos)).T @ tau

    def frame_jacobian(self, qpos, body: str) -> np.ndarray:
        """Jacobian (6 x nv, MuJoCo's velocity coordinates) of the hydro frame of `body`, in the
        frame's own axes (pin.LOCAL), linear first (= Fossen's order)."""
        q = self.q_pin(qpos)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        J = pin.getFrameJacobian(self.model, self.data, self.frames[body], pin.ReferenceFrame.LOCAL)
        return J @ np.linalg.inv(self.T(qpos))

    def frame_acceleration_at_rest(self, qpos, qvel, body: str) -> np.ndarray:
        """Classical acceleration (linear: of the frame origin; angular) of the hydro frame of
        `body` at qacc_mj = 0, in the frame's axes (pin.LOCAL), linear first."""
        q = self.q_pin(qpos)
        v = self.v_pin(qpos, qvel)
        a = np.zeros(self.model.nv)
        a[:3] = -np.cross(v[3:6], v[:3])
        pin.forwardKinematics(self.model, self.data, q, v, a)
        pin.updateFramePlacements(self.model, self.data)
        acc = pin.getFrameClassicalAcceleration(self.model, self.data, self.frames[body], pin.ReferenceFrame.LOCAL)
        return np.r_[acc.linear, acc.angular]
