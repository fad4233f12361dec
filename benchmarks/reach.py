"""How high can the Go1 lift one front foot while standing on the other three? Measured.

A hand-made quasi-static controller drives the dance scene (`quaddance.sim.scene`, the same
PD position actuators, gains and effort limits the policy uses) in native MuJoCo:

1. settle in the standing pose;
2. shift the centre of mass over the support triangle of the three stance feet, with a
   margin, by moving the trunk over the fixed feet (leg inverse kinematics);
3. lift the chosen front foot toward a target height ``h``, up and forward from under its
   hip (height first, place second), ramping over ``lift_s``; hold ``hold_s``.

While the leg lifts, the trunk keeps moving so that the whole-body centre of mass stays at
the same point of the triangle. The controller runs at the policy's 50 Hz and, as a policy
would learn to, offsets the position targets: by the plan's static joint torques / kp (a
gravity feed-forward: the soft kp 20 joints would sag by up to 0.2 rad under the weight), by
extra feedback on the stance joints' errors, and, during the hold, by an integral on the
lifted foot's height error.

A height counts as reached when the robot did not fall, the stance feet stayed on the floor
and the lifted foot's height held at least ``reached_fraction`` of ``h``. `measure_reach`
sweeps ``h`` coarsely and bisects the edge; `kinematic_reach` gives the joint-range bound.
"""

from __future__ import annotations

import functools
import math
import os
import platform
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import mujoco
import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.robots import GO1, RobotCfg
from quaddance.sim.scene import SceneCfg, build_model

LIFTABLE_FEET: tuple[str, ...] = ("FL", "FR")

#: The sweep the issue suggests: 0.05 ... 0.45 m in 0.025 m steps.
DEFAULT_HEIGHTS_M: tuple[float, ...] = tuple(round(0.05 + 0.025 * i, 3) for i in range(17))

_PARTS = ("hip", "thigh", "calf")
_DAMPING = 1e-4  # damped least squares (m^2); well below a leg's squared Jacobian scale
_MIN_LOAD_SHARE = 0.01  # while it unloads, the lifted foot's load weight tops out at 1 / this


@dataclass(frozen=True)
class ReachCfg:
    """Controller, timing and success settings of the reach test. Times in s, lengths in m."""

    settle_s: float = 0.5  # standing pose from the "home" keyframe; estimate (sag is over)
    shift_s: float = 1.0  # centre-of-mass shift ramp; slow enough to be quasi-static
    shift_hold_s: float = 0.5  # let the shifted stance settle before lifting
    lift_s: float = 1.0  # the issue: ramp the foot slowly, about 1 s
    hold_s: float = 1.0  # the issue: hold 1 s
    control_hz: float = 50.0  # the policy's rate (released code: 5 ms x decimation 4)
    #: Centre of mass kept this far inside the support triangle. Estimate: 3 cm is about
    #: a quarter of the triangle's inradius (0.11 m) and leaves room for the sway of a lift.
    com_margin_m: float = 0.03
    #: Extra proportional feedback on the stance joints' errors, as a fraction of kp.
    #: Measured here: with kp 20 alone, or with 1, the trunk sways sideways off three legs
    #: and the robot tips over during the lift; 2 holds the plan to a few mm.
    stiffening: float = 2.0
    #: The lifted foot is asked to move this far forward per metre of lift (second to its
    #: height). Measured here: 0.5 ends at the leg's highest point in front of the hip;
    #: 0 folds the leg under the hip, which stops 8 cm lower.
    forward_per_lift: float = 0.5
    #: Integral gain on the lifted foot's height error during the hold, 1/s, against the
    #: few millimetres a slightly tilted trunk costs (gone in about 0.2 s); its bound, m.
    height_gain_per_s: float = 5.0
    max_height_offset_m: float = 0.03
    ik_iterations: int = 3  # per control step, warm-started: the plan moves a little each step
    # Success criteria (the issue).
    min_trunk_height_m: float = 0.15
    max_tilt_deg: float = 30.0
    max_stance_foot_height_m: float = 0.01
    reached_fraction: float = 0.95
    #: The lifted foot's height is averaged over this last part of the hold.
    measure_window_s: float = 0.5

    def __post_init__(self) -> None:
        positive = {
            "settle_s": self.settle_s,
            "shift_s": self.shift_s,
            "lift_s": self.lift_s,
            "hold_s": self.hold_s,
            "control_hz": self.control_hz,
            "measure_window_s": self.measure_window_s,
            "ik_iterations": self.ik_iterations,
        }
        for name, value in positive.items():
            if not (np.isfinite(value) and value > 0):
                raise QuaddanceError(f"ReachCfg.{name} must be positive, got {value}")
        if not 0.0 < self.reached_fraction <= 1.0:
            raise QuaddanceError(
                f"ReachCfg.reached_fraction must be in (0, 1], got {self.reached_fraction}"
            )
        if self.com_margin_m < 0.0 or self.shift_hold_s < 0.0:
            raise QuaddanceError("ReachCfg.com_margin_m and shift_hold_s must not be negative")


@dataclass
class _Trial:
    """Outcome of one lift to ``target_m``."""

    target_m: float
    success: bool
    reason: str  # "ok", "fell", "stance foot lifted", "leg in trunk" or "too low"
    reached_m: float  # lifted foot height, mean over the measuring window
    peak_m: float  # highest lifted foot height seen
    min_trunk_height_m: float
    max_tilt_deg: float
    max_stance_foot_height_m: float
    max_stance_slip_m: float  # horizontal, from where the stance feet stood
    #: Closest approach of the lifted leg to the trunk at the end, < 0 if inside: the scene
    #: has no self-collision, so this keeps a leg from "reaching" through the body.
    leg_trunk_gap_m: float


def _smoothstep(x: float) -> float:
    """Minimum-jerk ramp 0 -> 1 over x in [0, 1]."""
    x = min(max(x, 0.0), 1.0)
    return x**3 * (10.0 - 15.0 * x + 6.0 * x * x)


def shrunk_triangle(tri_xy: np.ndarray, margin_m: float) -> np.ndarray:
    """Triangle (3, 2) with every edge moved ``margin_m`` inward.

    The inner parallel triangle is the original scaled about its incentre by (r - m) / r,
    r the inradius.
    """
    a = np.linalg.norm(tri_xy[1] - tri_xy[2])
    b = np.linalg.norm(tri_xy[2] - tri_xy[0])
    c = np.linalg.norm(tri_xy[0] - tri_xy[1])
    incentre = (a * tri_xy[0] + b * tri_xy[1] + c * tri_xy[2]) / (a + b + c)
    e1, e2 = tri_xy[1] - tri_xy[0], tri_xy[2] - tri_xy[0]
    area = 0.5 * abs(e1[0] * e2[1] - e1[1] * e2[0])
    inradius = 2.0 * area / (a + b + c)
    if margin_m >= inradius:
        raise QuaddanceError(
            f"com_margin_m {margin_m} m does not fit the support triangle "
            f"(inradius {inradius:.3f} m)"
        )
    return incentre + (tri_xy - incentre) * (inradius - margin_m) / inradius


def closest_point_in_triangle(p_xy: np.ndarray, tri_xy: np.ndarray) -> np.ndarray:
    """The point of the triangle (3, 2) nearest to ``p_xy`` (2,); ``p_xy`` if inside."""
    signs = []
    for i in range(3):
        e = tri_xy[(i + 1) % 3] - tri_xy[i]
        d = p_xy - tri_xy[i]
        signs.append(e[0] * d[1] - e[1] * d[0])
    if all(s >= 0 for s in signs) or all(s <= 0 for s in signs):
        return p_xy.copy()
    best, best_d = p_xy, np.inf
    for i in range(3):
        a, b = tri_xy[i], tri_xy[(i + 1) % 3]
        t = np.clip(np.dot(p_xy - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        q = a + t * (b - a)
        if (d := np.linalg.norm(p_xy - q)) < best_d:
            best, best_d = q, d
    return best


def _tilt_deg(quat_wxyz: np.ndarray) -> float:
    """Angle between the trunk's z axis and the world's z axis, degrees."""
    _, x, y, _ = quat_wxyz
    cos_tilt = 1.0 - 2.0 * (x * x + y * y)
    return math.degrees(math.acos(min(max(cos_tilt, -1.0), 1.0)))


class _Planner:
    """Kinematic whole-body plan: joint targets that put the feet and the centre of mass where
    asked, for a level trunk at a fixed height (only the trunk's x, y move).

    Works on its own MjData, so planning never touches the simulated state.
    """

    def __init__(self, model: mujoco.MjModel, qpos: np.ndarray, legs: tuple[str, ...]) -> None:
        self.model = model
        self.kin = mujoco.MjData(model)
        self.kin.qpos[:] = qpos
        yaw = 2.0 * math.atan2(qpos[6], qpos[3])  # keep the heading, level the trunk
        self.kin.qpos[3:7] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        self.legs = {
            leg: (
                np.array([model.joint(f"{leg}_{p}_joint").qposadr[0] for p in _PARTS]),
                np.array([model.joint(f"{leg}_{p}_joint").dofadr[0] for p in _PARTS]),
                model.site(leg).id,
            )
            for leg in legs
        }
        self.joint_lo = model.jnt_range[1:, 0].copy()  # model joint order (after the base)
        self.joint_hi = model.jnt_range[1:, 1].copy()
        self.jacp = np.zeros((3, model.nv))
        self._forward()

    def _forward(self) -> None:
        mujoco.mj_kinematics(self.model, self.kin)
        mujoco.mj_comPos(self.model, self.kin)

    def com_xy(self) -> np.ndarray:
        return self.kin.subtree_com[1, :2].copy()

    def foot_w(self, leg: str) -> np.ndarray:
        return self.kin.site_xpos[self.legs[leg][2]].copy()

    def to_world_xy(self, offset_b_xy: np.ndarray) -> np.ndarray:
        """A trunk-frame horizontal offset from the trunk origin, in world x, y."""
        rot = self.kin.xmat[1].reshape(3, 3)
        return self.kin.qpos[:2] + rot[:2, :2] @ offset_b_xy

    def to_trunk_xy(self, point_w: np.ndarray) -> np.ndarray:
        rot = self.kin.xmat[1].reshape(3, 3)
        return rot[:2, :2].T @ (point_w[:2] - self.kin.qpos[:2])

    def joint_targets(self) -> np.ndarray:
        return self.kin.qpos[7:].copy()

    def solve(
        self,
        stance_w: dict[str, np.ndarray],
        com_xy: np.ndarray,
        swing: tuple[str, float, np.ndarray] | None,
        iterations: int,
    ) -> np.ndarray:
        """Joint targets (12,) rad, model order.

        ``stance_w``: world position (3,) of each foot site to hold; ``com_xy``: where the
        centre of mass should be; ``swing``: (leg, foot-site z, preferred trunk-frame x, y of
        the foot) for the lifted leg - its height comes first, the x, y only after that.
        """
        qpos = self.kin.qpos
        for _ in range(iterations):
            self._forward()
            # The trunk carries most of the mass: moving it by the CoM error nearly fixes it.
            qpos[:2] += com_xy - self.com_xy()
            self._forward()
            for leg, target in stance_w.items():
                err = target - self.kin.site_xpos[self.legs[leg][2]]
                self._leg_step(leg, lambda jac, e=err: _dls_step(jac, e))
            if swing is not None:
                leg, z_target, pref_b_xy = swing
                foot = self.kin.site_xpos[self.legs[leg][2]]
                err_z, err_xy = z_target - foot[2], self.to_world_xy(pref_b_xy) - foot[:2]
                self._leg_step(
                    leg,
                    lambda jac, ez=err_z, exy=err_xy: _prioritised_step(jac, ez, exy),
                    thigh_max=math.pi,  # the thigh does not swing back past vertical
                )
        self._forward()
        return self.joint_targets()

    def holding_torques(self, load_weights: dict[str, float]) -> np.ndarray:
        """Joint torques (12,) N m, model order, that hold the planned pose still.

        The feet in ``load_weights`` push straight up; they share the weight so as to
        minimise the sum of force^2 * weight (a heavy weight unloads a foot), under the trunk's
        force and moment balance. Feet not named carry nothing.
        """
        nv = self.model.nv
        gravity = np.zeros(nv)
        mujoco.mj_rne(self.model, self.kin, 0, gravity)  # qvel = 0: gravity alone
        legs = list(load_weights)
        jz = np.zeros((len(legs), nv))
        for i, leg in enumerate(legs):
            mujoco.mj_jacSite(self.model, self.kin, self.jacp, None, self.legs[leg][2])
            jz[i] = self.jacp[2]
        # Trunk rows: the vertical foot forces f balance gravity, jz[:, :6].T @ f = g[:6];
        # the weighted minimum-norm solution through the scaling f = scale * u.
        scale = 1.0 / np.sqrt(np.array([load_weights[leg] for leg in legs]))
        u = np.linalg.lstsq(jz[:, :6].T * scale, gravity[:6], rcond=1e-9)[0]
        forces = scale * u
        return (gravity - jz.T @ forces)[6:]

    def _leg_step(
        self,
        leg: str,
        step_of: Callable[[np.ndarray], np.ndarray],
        thigh_max: float | None = None,
    ) -> None:
        """One IK step of ``leg``: ``step_of(jac)`` maps the (3, 3) foot Jacobian to a joint
        step; a joint held at a limit is taken out of the Jacobian, so that the others do
        its share instead of the step being lost to clipping."""
        q_adr, dof_adr, site = self.legs[leg]
        mujoco.mj_jacSite(self.model, self.kin, self.jacp, None, site)
        jac = self.jacp[:, dof_adr].copy()
        j = q_adr - 7
        lo, hi = self.joint_lo[j], self.joint_hi[j].copy()
        if thigh_max is not None:
            hi[1] = min(hi[1], thigh_max)
        q = self.kin.qpos[q_adr]
        free = np.ones(3, dtype=bool)
        for _ in range(3):
            # Small steps keep the linearisation valid; the plan is re-solved every step.
            step = np.clip(step_of(jac * free), -0.2, 0.2)
            held = free & (((q <= lo) & (step < 0)) | ((q >= hi) & (step > 0)))
            if not held.any():
                break
            free &= ~held
        self.kin.qpos[q_adr] = np.clip(q + step, lo, hi)


def _dls_step(jac: np.ndarray, err: np.ndarray) -> np.ndarray:
    """Damped least-squares joint step (3,) moving a foot by ``err`` (3,) m; ``jac`` (3, 3)."""
    return jac.T @ np.linalg.solve(jac @ jac.T + _DAMPING * np.eye(3), err)


def _prioritised_step(jac: np.ndarray, err_z: float, err_xy: np.ndarray) -> np.ndarray:
    """Joint step (3,) for one leg: foot height first, then x, y in the remaining freedom.

    ``jac`` (3, 3): foot position Jacobian of the leg's joints; errors in m.
    """
    jz = jac[2:3]
    jz_pinv = jz.T / (jz @ jz.T + _DAMPING)
    dq = (jz_pinv * err_z).ravel()
    null = np.eye(3) - jz_pinv @ jz
    jxy = jac[:2] @ null
    rest = err_xy - jac[:2] @ dq
    dq += null @ (jxy.T @ np.linalg.solve(jxy @ jxy.T + _DAMPING * np.eye(2), rest))
    return dq


@dataclass
class _Stance:
    """The simulation state once the centre of mass is over the triangle; lifts start here."""

    data: mujoco.MjData
    planner_qpos: np.ndarray
    stance_w: dict[str, np.ndarray]
    com_target_xy: np.ndarray
    swing_start_z: float
    swing_pref_b_xy: np.ndarray
    worst: dict[str, float]


class _ReachRig:
    """One foot's reach test: the model, the planner, and the shared shifted stance."""

    def __init__(self, foot: str, cfg: ReachCfg, scene: SceneCfg) -> None:
        if foot not in LIFTABLE_FEET:
            raise QuaddanceError(f"foot must be one of {LIFTABLE_FEET}, got {foot!r}")
        self.foot, self.cfg, self.robot = foot, cfg, scene.robot
        self.model = build_model(scene, visual=False)
        self.kp = self.model.actuator_gainprm[:, 0].copy()
        self.stance_legs = tuple(leg for leg in self.robot.feet if leg != foot)
        # Only the stance legs are stiffened: the light lifted leg, fed its gravity torque,
        # holds still without it, and buzzes with it (extra gain applied at the control rate).
        self.stiffened = np.array([leg != foot for leg in self.robot.legs for _ in _PARTS])
        self.site = {leg: self.model.site(leg).id for leg in self.robot.feet}
        model = self.model
        colliding = [g for g in range(model.ngeom) if model.geom_contype[g]]
        leg_bodies = {model.body(f"{foot}_{p}").id for p in ("thigh", "calf")}
        self.trunk_geoms = [g for g in colliding if model.geom_bodyid[g] == 1]
        self.leg_geoms = [g for g in colliding if model.geom_bodyid[g] in leg_bodies]
        self.steps_per_ctrl = max(1, round(1.0 / (cfg.control_hz * self.model.opt.timestep)))
        self.dt_ctrl_s = self.steps_per_ctrl * self.model.opt.timestep
        self.standing_qpos, self.stance = self._shift()

    def _n_ctrl(self, duration_s: float) -> int:
        return max(1, round(duration_s / self.dt_ctrl_s))

    def _step(self, data: mujoco.MjData, q_plan: np.ndarray, tau_nm: np.ndarray) -> None:
        """Hold the plan for one control period: targets ``q_plan`` (12,) rad, offset so that
        the PD joints give the holding torques ``tau_nm`` (12,) there."""
        error = q_plan - data.qpos[7:]
        data.ctrl[:] = q_plan + tau_nm / self.kp + self.cfg.stiffening * error * self.stiffened
        mujoco.mj_step(self.model, data, nstep=self.steps_per_ctrl)

    def _foot_height(self, data: mujoco.MjData, leg: str) -> float:
        return float(data.site_xpos[self.site[leg], 2]) - self.robot.foot_radius_m

    def _shift(self) -> tuple[np.ndarray, _Stance]:
        cfg, model = self.cfg, self.model
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
        mujoco.mj_forward(model, data)
        planner = _Planner(model, data.qpos, self.robot.legs)
        all_feet = dict.fromkeys(self.robot.feet, 1.0)
        q_home, tau_home = planner.joint_targets(), planner.holding_torques(all_feet)
        for _ in range(self._n_ctrl(cfg.settle_s)):
            self._step(data, q_home, tau_home)
        standing_qpos = data.qpos.copy()

        planner = _Planner(model, standing_qpos, self.robot.legs)
        feet_w = {leg: data.site_xpos[self.site[leg]].copy() for leg in self.robot.feet}
        # The lifted foot's path starts from where it stands relative to the trunk.
        swing_pref_b_xy = planner.to_trunk_xy(feet_w[self.foot])
        tri_xy = np.array([feet_w[leg][:2] for leg in self.stance_legs])
        com0 = data.subtree_com[1, :2].copy()
        com_target = closest_point_in_triangle(com0, shrunk_triangle(tri_xy, cfg.com_margin_m))
        # All four feet stay down while the trunk carries the centre of mass over; the
        # lifted foot's share of the weight goes to the others on the way.
        planner.solve(feet_w, com0, None, iterations=10)
        worst = {"stance": -np.inf, "trunk": np.inf, "tilt": 0.0, "slip": 0.0}
        n_shift, n_hold = self._n_ctrl(cfg.shift_s), self._n_ctrl(cfg.shift_hold_s)
        for k in range(n_shift + n_hold):
            s = _smoothstep((k + 1) / n_shift)
            q_plan = planner.solve(feet_w, com0 + s * (com_target - com0), None, cfg.ik_iterations)
            loads = dict.fromkeys(self.stance_legs, 1.0)
            loads[self.foot] = 1.0 / max(1.0 - s, _MIN_LOAD_SHARE)
            self._step(data, q_plan, planner.holding_torques(loads))
            self._track(data, worst, feet_w)
        return standing_qpos, _Stance(
            data=data,
            planner_qpos=planner.kin.qpos.copy(),
            stance_w={leg: feet_w[leg] for leg in self.stance_legs},
            com_target_xy=com_target,
            swing_start_z=float(data.site_xpos[self.site[self.foot], 2]),
            swing_pref_b_xy=swing_pref_b_xy,
            worst=worst,
        )

    def _track(
        self, data: mujoco.MjData, worst: dict[str, float], feet_w: dict[str, np.ndarray]
    ) -> None:
        """Update the worst stance foot height and slip, trunk height and tilt so far."""
        for leg in self.stance_legs:
            foot_w = data.site_xpos[self.site[leg]]
            worst["stance"] = max(worst["stance"], self._foot_height(data, leg))
            worst["slip"] = max(worst["slip"], float(np.linalg.norm(foot_w[:2] - feet_w[leg][:2])))
        worst["trunk"] = min(worst["trunk"], float(data.qpos[2]))
        worst["tilt"] = max(worst["tilt"], _tilt_deg(data.qpos[3:7]))

    def _fell(self, worst: dict[str, float]) -> bool:
        return worst["trunk"] < self.cfg.min_trunk_height_m or worst["tilt"] > self.cfg.max_tilt_deg

    def lift(self, target_m: float) -> _Trial:
        """Lift the foot to ``target_m`` (foot bottom above the floor, m) from the stance."""
        cfg, st = self.cfg, self.stance
        data = mujoco.MjData(self.model)
        mujoco.mj_copyData(data, self.model, st.data)
        planner = _Planner(self.model, st.planner_qpos, self.robot.legs)
        worst = dict(st.worst)
        loads = dict.fromkeys(self.stance_legs, 1.0)
        z_goal = target_m + self.robot.foot_radius_m
        n_lift, n_hold = self._n_ctrl(cfg.lift_s), self._n_ctrl(cfg.hold_s)
        n_window = min(n_hold, self._n_ctrl(cfg.measure_window_s))
        heights: list[float] = []
        z_offset = 0.0  # integral of the lifted foot's height error, m
        for k in range(n_lift + n_hold):
            z_plan = st.swing_start_z + _smoothstep((k + 1) / n_lift) * (z_goal - st.swing_start_z)
            if k >= n_lift:  # during the hold only: a ramp's lag is no bias to integrate
                z_offset += (
                    cfg.height_gain_per_s
                    * self.dt_ctrl_s
                    * (z_plan - self.robot.foot_radius_m - heights[-1])
                )
                z_offset = min(max(z_offset, -cfg.max_height_offset_m), cfg.max_height_offset_m)
            z = z_plan + z_offset
            # The foot rises along a forward slope: a leg folded under its hip stops short of
            # the height a forward-reaching one gets to.
            forward_m = cfg.forward_per_lift * (z_plan - st.swing_start_z)
            pref_b_xy = st.swing_pref_b_xy + np.array([forward_m, 0.0])
            q_plan = planner.solve(
                st.stance_w, st.com_target_xy, (self.foot, z, pref_b_xy), cfg.ik_iterations
            )
            self._step(data, q_plan, planner.holding_torques(loads))
            self._track(data, worst, st.stance_w)
            heights.append(self._foot_height(data, self.foot))
            if self._fell(worst):
                break
        reached = float(np.mean(heights[-n_window:]))
        gap = self._leg_trunk_gap(data)
        if self._fell(worst):
            reason = "fell"
        elif worst["stance"] > cfg.max_stance_foot_height_m:
            reason = "stance foot lifted"
        elif gap < 0.0:
            reason = "leg in trunk"
        elif reached < cfg.reached_fraction * target_m:
            reason = "too low"
        else:
            reason = "ok"
        return _Trial(
            target_m=float(target_m),
            success=reason == "ok",
            reason=reason,
            reached_m=reached,
            peak_m=float(max(heights)),
            min_trunk_height_m=worst["trunk"],
            max_tilt_deg=worst["tilt"],
            max_stance_foot_height_m=worst["stance"],
            max_stance_slip_m=worst["slip"],
            leg_trunk_gap_m=gap,
        )

    def _leg_trunk_gap(self, data: mujoco.MjData) -> float:
        fromto = np.zeros(6)
        return min(
            mujoco.mj_geomDistance(self.model, data, a, b, 0.1, fromto)
            for a in self.leg_geoms
            for b in self.trunk_geoms
        )


def kinematic_reach(
    foot: str = "FL",
    scene: SceneCfg = SceneCfg(),
    base_qpos: np.ndarray | None = None,
    in_front: bool = False,
    grid_points: int = 21,
) -> dict[str, Any]:
    """Highest foot height (foot bottom above the floor, m) over the leg's joint ranges with
    the trunk held still.

    The thigh may turn from its forward limit up to vertical upward (pi rad), not past it;
    collisions are ignored. ``in_front=True`` also keeps the foot in front of (or below) the
    hip, as in the physics test; without it the best pose folds the leg up behind the hip,
    through where the trunk is. ``base_qpos`` (19,): the robot's pose (default: the "home"
    keyframe); only the trunk pose matters. A grid of ``grid_points`` per joint is refined
    twice around its best point.

    Returns ``{"height_m", "joint_pos_rad" (hip, thigh, calf), "foot_pos_w_m" (3,)}``.
    """
    if foot not in scene.robot.feet:
        raise QuaddanceError(f"foot must be one of {scene.robot.feet}, got {foot!r}")
    model = build_model(scene, visual=False)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    if base_qpos is not None:
        data.qpos[:] = base_qpos
    joints = [model.joint(f"{foot}_{p}_joint") for p in _PARTS]
    q_adr = np.array([j.qposadr[0] for j in joints])
    lo = np.array([j.range[0] for j in joints])
    hi = np.array([j.range[1] for j in joints])
    hi[1] = min(hi[1], math.pi)
    site, hip = model.site(foot).id, model.body(f"{foot}_hip").id

    def height(q: np.ndarray) -> float:
        data.qpos[q_adr] = q
        mujoco.mj_kinematics(model, data)
        foot_w = data.site_xpos[site]
        if in_front:
            forward_w = data.xmat[1].reshape(3, 3)[:, 0]
            if np.dot(foot_w - data.xpos[hip], forward_w) < 0.0:
                return -np.inf
        return float(foot_w[2]) - scene.robot.foot_radius_m

    best_q, best_h = (lo + hi) / 2, -np.inf
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    for _ in range(3):
        axes = [
            np.linspace(max(lo[i], c - h), min(hi[i], c + h), grid_points)
            for i, (c, h) in enumerate(zip(centre, half, strict=True))
        ]
        for q in np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3):
            if (h := height(q)) > best_h:
                best_q, best_h = q.copy(), h
        centre, half = best_q, 2.0 * half / (grid_points - 1)
    height(best_q)
    return {
        "height_m": best_h,
        "joint_pos_rad": best_q.tolist(),
        "foot_pos_w_m": data.site_xpos[site].tolist(),
    }


def measure_reach(
    foot: str = "FL",
    heights: tuple[float, ...] | np.ndarray = DEFAULT_HEIGHTS_M,
    tolerance_m: float = 0.005,
    cfg: ReachCfg = ReachCfg(),
    scene: SceneCfg = SceneCfg(),
    stop_after_failures: int = 2,
    progress: Callable[[dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Largest height (foot bottom above the floor, m) the ``foot`` ("FL" or "FR") can be
    lifted to and held while the robot stands on its other three legs, in the dance scene.

    ``heights`` (n,) m: the coarse sweep, tried in increasing order until
    ``stop_after_failures`` failures in a row; the gap above the highest success is then
    bisected down to ``tolerance_m``. Every trial starts from the same shifted stance.
    ``progress`` is called with each trial's dict as it ends.

    Returns a dict:

    - ``reach_m``: highest target reached (0.0 if none); ``held_m``: the height the foot held
      in that trial (it may be up to ``1 - reached_fraction`` below the target);
      ``first_failure_m``: the lowest failed target above it (None if none failed);
    - ``kinematic_bound_m`` / ``kinematic_bound_front_m``: `kinematic_reach` from the
      standing pose, anywhere / in front of the hip;
    - ``trunk_height_m``: the standing trunk height; ``com_shift_m``: how far the centre of
      mass moved to stand over the triangle;
    - ``trials``: one dict per trial, by target (see `_Trial`); ``cfg``: the settings.
    """
    targets = np.sort(np.asarray(heights, dtype=float).ravel())
    if targets.size == 0 or not np.all(np.isfinite(targets)) or targets[0] <= 0:
        raise QuaddanceError(f"heights must be positive numbers (m), got {heights!r}")
    if not tolerance_m > 0:
        raise QuaddanceError(f"tolerance_m must be positive, got {tolerance_m}")
    rig = _ReachRig(foot, cfg, scene)
    trials: list[_Trial] = []

    def run(target_m: float) -> _Trial:
        trial = rig.lift(target_m)
        trials.append(trial)
        if progress is not None:
            progress(asdict(trial))
        return trial

    failures_in_a_row = 0
    for h in targets:
        failures_in_a_row = 0 if run(float(h)).success else failures_in_a_row + 1
        if failures_in_a_row >= stop_after_failures:
            break
    best = max((t for t in trials if t.success), key=lambda t: t.target_m, default=None)
    reach = best.target_m if best is not None else 0.0
    fail = min((t.target_m for t in trials if not t.success and t.target_m > reach), default=None)
    if best is not None and fail is not None:
        while fail - best.target_m > tolerance_m:
            trial = run(0.5 * (best.target_m + fail))
            if trial.success:
                best = trial
            else:
                fail = trial.target_m
    standing = rig.standing_qpos
    return {
        "foot": foot,
        "reach_m": best.target_m if best is not None else 0.0,
        "held_m": best.reached_m if best is not None else 0.0,
        "first_failure_m": fail,
        "kinematic_bound_m": kinematic_reach(foot, scene, standing)["height_m"],
        "kinematic_bound_front_m": kinematic_reach(foot, scene, standing, in_front=True)[
            "height_m"
        ],
        "trunk_height_m": float(standing[2]),
        "com_shift_m": float(
            np.linalg.norm(rig.stance.com_target_xy - _com_xy(rig.model, standing))
        ),
        "trials": [asdict(t) for t in sorted(trials, key=lambda t: t.target_m)],
        "cfg": asdict(cfg),
    }


def _com_xy(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """Horizontal position of the whole robot's centre of mass in pose ``qpos`` (19,), m."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    return data.subtree_com[1, :2].copy()


def reach_report(
    feet: tuple[str, ...] = LIFTABLE_FEET,
    heights: tuple[float, ...] | np.ndarray = DEFAULT_HEIGHTS_M,
    tolerance_m: float = 0.005,
    cfg: ReachCfg = ReachCfg(),
    progress: Callable[[str, dict[str, Any]], None] | None = None,
    robot: RobotCfg = GO1,
) -> dict[str, Any]:
    """`measure_reach` for each of ``feet`` with its wall time, as the `bench reach` JSON.

    ``progress(foot, trial)`` is called after every trial. ``held_m_min`` is the lowest
    height held at the reach over the feet: the robot's reachable front-foot height.
    """
    per_foot = {}
    for foot in feet:
        t0 = time.perf_counter()
        result = measure_reach(
            foot,
            heights,
            tolerance_m,
            cfg,
            SceneCfg(robot=robot),
            progress=None if progress is None else functools.partial(progress, foot),
        )
        result["wall_s"] = round(time.perf_counter() - t0, 3)
        result["n_trials"] = len(result["trials"])
        per_foot[foot] = result
    return {
        "benchmark": "reach",
        "what": "highest front-foot height held standing on three legs (quasi-static "
        "controller in native MuJoCo, dance scene), and the time to measure it",
        "robot": robot.name,
        "reach_m_min": min(r["reach_m"] for r in per_foot.values()),
        "held_m_min": min(r["held_m"] for r in per_foot.values()),
        "kinematic_bound_front_m": min(r["kinematic_bound_front_m"] for r in per_foot.values()),
        "feet": per_foot,
        "machine": {
            "python": platform.python_version(),
            "mujoco": mujoco.__version__,
            "cpu": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(),
        },
    }
