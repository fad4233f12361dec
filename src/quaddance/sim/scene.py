"""The dance scene: the robot (`SceneCfg.robot`, mjlab's Go1 by default) on a flat floor,
with PD position actuators and sensors.

One MJCF for every engine (native MuJoCo, MuJoCo Warp) and for rendering, built from the
robot's model file and cached per setting.
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass

import mujoco
import numpy as np

from quaddance.robots import GO1, RobotCfg


@dataclass(frozen=True)
class SceneCfg:
    """The robot and the physics settings of the scene.

    ``kp`` and ``kd`` (the position actuators' gains) default to the robot's; they are filled
    in at construction, so a saved task (the policy JSON's ``task``) records the numbers
    (and `dataclasses.replace` with another robot keeps them: construct a new config).
    """

    robot: RobotCfg = GO1
    timestep_s: float = 0.005  # released code: sim dt 0.005 s
    kp: float | None = None  # None: `RobotCfg.kp`
    kd: float | None = None  # None: `RobotCfg.kd`
    foot_friction: float = 1.0
    solver_iterations: int = 8
    ls_iterations: int = 8

    def __post_init__(self) -> None:
        if self.kp is None:
            object.__setattr__(self, "kp", self.robot.kp)
        if self.kd is None:
            object.__setattr__(self, "kd", self.robot.kd)


def build_spec(cfg: SceneCfg = SceneCfg(), visual: bool = True) -> mujoco.MjSpec:
    """Robot + floor + actuators + sensors as an editable spec.

    ``visual=False`` drops the visual meshes (39 MB of model buffer): the dynamics are the
    same because every body has an explicit inertial and visual geoms never collide.
    """
    robot = cfg.robot
    spec = mujoco.MjSpec.from_file(robot.model_file())
    # Our own sensors replace the model's IMU sensors (one fewer thing to compute per step).
    for sensor in list(spec.sensors):
        spec.delete(sensor)
    if not visual:
        for geom in list(spec.geoms):
            if geom.type == mujoco.mjtGeom.mjGEOM_MESH:
                spec.delete(geom)
        for mesh in list(spec.meshes):
            spec.delete(mesh)
    spec.option.timestep = cfg.timestep_s
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.iterations = cfg.solver_iterations
    spec.option.ls_iterations = cfg.ls_iterations
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 720

    # Floor: a checker plane. Robot geoms collide with the floor only (no self-collision):
    # robot contype=1/conaffinity=0, floor conaffinity=1.
    tex = spec.add_texture(
        name="grid",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        width=512,
        height=512,
        rgb1=[0.82, 0.82, 0.86],
        rgb2=[0.70, 0.70, 0.76],
    )
    mat = spec.add_material(name="floor", texrepeat=[4, 4], reflectance=0.0)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = tex.name
    spec.add_texture(
        name="sky",
        type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
        width=256,
        height=256,
        rgb1=[0.35, 0.45, 0.65],
        rgb2=[0.05, 0.05, 0.12],
    )
    world = spec.worldbody
    world.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0, 0, 0.05],
        material="floor",
        contype=1,
        conaffinity=1,
        condim=3,
    )
    world.add_light(
        pos=[0, 0, 3],
        dir=[0, 0, -1],
        diffuse=[0.6, 0.6, 0.6],
        type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
    )

    for geom in spec.geoms:
        if geom.name.endswith("_collision") or "_collision" in geom.name:
            # One friction for every robot geom; priority makes it override the floor's.
            geom.contype, geom.conaffinity, geom.condim = 1, 0, 3
            geom.friction = [cfg.foot_friction, 0.005, 0.0001]
            geom.priority = 1

    for name, armature, effort in zip(
        robot.joint_names, robot.armature, robot.effort_limit_nm, strict=True
    ):
        spec.joint(name).armature = armature
        act = spec.add_actuator(name=name.removesuffix("_joint"), target=name)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_position(kp=cfg.kp, kv=cfg.kd)
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-effort, effort]

    # Sensors, read by every engine in this order (see quaddance.sim.state.SensorLayout).
    site, actuator = mujoco.mjtObj.mjOBJ_SITE, mujoco.mjtObj.mjOBJ_ACTUATOR
    feet = list(zip(robot.feet, robot.foot_sites, strict=True))
    sensors = [(f"{f}_pos", mujoco.mjtSensor.mjSENS_FRAMEPOS, site, s) for f, s in feet]
    sensors += [(f"{f}_vel", mujoco.mjtSensor.mjSENS_FRAMELINVEL, site, s) for f, s in feet]
    sensors += [
        (f"{j}_torque", mujoco.mjtSensor.mjSENS_ACTUATORFRC, actuator, j.removesuffix("_joint"))
        for j in robot.joint_names
    ]
    for name, sensor_type, objtype, objname in sensors:
        spec.add_sensor(name=name, type=sensor_type, objtype=objtype, objname=objname)
    # Contacts with the floor of the trunk (termination) and of the thighs and the upper calf
    # capsules near the knees (collision penalty); the calf bodies also hold the feet.
    contacts = [("trunk", mujoco.mjtObj.mjOBJ_BODY, robot.trunk_body)]
    for leg, thigh, knee in zip(robot.legs, robot.thigh_bodies, robot.knee_geoms, strict=True):
        contacts.append((f"{leg}_thigh", mujoco.mjtObj.mjOBJ_BODY, thigh))
        contacts.append((f"{leg}_knee", mujoco.mjtObj.mjOBJ_GEOM, knee))
    for name, objtype, objname in contacts:
        spec.add_sensor(
            name=f"{name}_contact",
            type=mujoco.mjtSensor.mjSENS_CONTACT,
            objtype=objtype,
            objname=objname,
            reftype=mujoco.mjtObj.mjOBJ_GEOM,
            refname="floor",
            intprm=[1, 0, 1],  # data="found", no reduction, num=1
        )
    # Nominal standing pose as the "home" keyframe.
    qpos = np.zeros(7 + robot.num_joints)
    qpos[2] = robot.init_base_height_m
    qpos[3] = 1.0
    qpos[7:] = robot.nominal_joint_pos_rad
    spec.add_key(name="home", qpos=qpos.tolist(), ctrl=list(robot.nominal_joint_pos_rad))
    return spec


@functools.lru_cache(maxsize=8)
def _compiled(cfg: SceneCfg, visual: bool) -> mujoco.MjModel:
    return build_spec(cfg, visual).compile()


def build_model(cfg: SceneCfg = SceneCfg(), visual: bool = False) -> mujoco.MjModel:
    """A fresh MjModel of the scene; compiled once per setting, then copied.

    Physics (training, playback) uses ``visual=False``; the renderer uses ``visual=True``.
    Both have the same bodies, joints, actuators, sensors and therefore the same qpos layout.
    """
    return copy.deepcopy(_compiled(cfg, visual))
