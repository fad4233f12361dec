"""The dance task's settings: one dataclass per concern, defaults naming their source."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from quaddance.sim.scene import SceneCfg

#: Where an actor observation term comes from on a real Go1 (the policy JSON's
#: `obs.terms[].source`); the critic's simulator-only terms say "privileged".
SOURCES: tuple[str, ...] = (
    "imu",
    "joint_encoders",
    "foot_contact",
    "kinematics",
    "dance",
    "previous_action",
)


@dataclass(frozen=True)
class ObsSlice:
    """One entry of an observation layout: a term's name, its number of columns and its
    sensor source (None in policy files that predate sources). The layouts are derived from
    the term tables of `quaddance.sim.observations`; the policy JSON's `obs.terms` holds them."""

    name: str
    size: int
    source: str | None = None


@dataclass
class RewardTerm:
    """One reward term: ``weight * fn(env, **params)``, times the policy step (a rate, as in
    legged_gym) or, with ``per_step`` false, paid once (an event such as a fall). ``fn`` is a
    function of `quaddance.sim.rewards`; ``curriculum``: its weight grows in with training's
    curriculum (`DanceEnv.curriculum_scale`)."""

    fn: Callable[..., Any]
    weight: float
    params: dict[str, Any] = field(default_factory=dict)
    curriculum: bool = False
    per_step: bool = True


@dataclass
class DomainRandCfg:
    """FACTS.md section 2 (released code), plus pushes. Restitution is not modelled: MuJoCo's
    soft contacts have no restitution coefficient."""

    enabled: bool = True
    num_variants: int = 16  # K model variants per engine; each env draws one at reset
    friction: tuple[float, float] = (0.1, 3.0)
    added_mass_kg: tuple[float, float] = (-1.0, 3.0)
    motor_strength: tuple[float, float] = (0.9, 1.1)
    joint_offset_rad: float = 0.02
    max_action_lag_substeps: int = 6  # 30 ms at 5 ms physics steps
    push_interval_s: float = 8.0
    push_vel_m_s: float = 0.5
    init_joint_noise_rad: float = 0.1
    # Sensor noise on what the actor measures, uniform +-value per reading: legged_gym's
    # noise_scales (Rudin et al. 2022), which Walk These Ways uses on a real Go1.
    sensor_noise: bool = True
    gravity_noise: float = 0.05  # projected gravity (unit vector) components
    gyro_noise_rad_s: float = 0.2
    joint_pos_noise_rad: float = 0.01
    joint_vel_noise_rad_s: float = 1.5
    heading_noise_rad: float = 0.02  # IMU heading since the dance began (whole-body, `obs.heading`)


@dataclass
class ObsCfg:
    """What the policy sees; see quaddance.sim.observations for the layout."""

    preview_s: tuple[float, ...] = (0.1, 0.2, 0.4)  # ours: upcoming front targets
    history_len: int = 3  # past proprioceptive frames stacked for the actor
    # Whole-body only: the trunk's heading since the dance began (IMU yaw) minus the target
    # yaw. Without it the actor cannot see the slow turn of the whole robot on its feet,
    # which was most of the yaw error (sim: 4.4 of 5.8 deg MAE on the demo song).
    heading: bool = False
    privileged_critic: bool = True  # asymmetric critic: friction, mass, strength, velocity


@dataclass
class DanceTaskCfg:
    """The dance task (one config for both engines, training and playback)."""

    num_envs: int = 256
    episode_length_s: float = 20.0
    policy_hz: float = 50.0
    decimation: int = 4  # released code: 0.005 s x 4
    action_scale: float = 0.25  # released code
    hip_scale_factor: float = 0.5  # released code: hips x0.5
    # Ours: add to each front leg the joint offsets that lift its foot to the target
    # (quaddance.sim.feedforward); the policy corrects and balances.
    front_feedforward: bool = True
    # Ours, beyond the paper: the trunk dances too. The dance's body targets (height offset,
    # roll, pitch, yaw; `quaddance.layout.BODY_COLUMNS`) enter the actor's observation, the
    # rewards track them, and a body feed-forward (quaddance.sim.body) moves all four legs
    # to hold the feet still while the trunk takes the pose.
    whole_body: bool = False
    # Terminations; None: the robot's (`RobotCfg.max_tilt_rad`, `min_base_height_m`).
    max_tilt_rad: float | None = None
    min_base_height_m: float | None = None
    # The standing trunk height the rewards and body metrics measure from; None: the
    # robot's `standing_height_m`.
    base_height_target_m: float | None = None
    scene: SceneCfg = field(default_factory=SceneCfg)
    # The reward terms by name, in the order they are summed; `quaddance.sim.tasks` builds
    # them for each task variant (a config without them computes no reward).
    rewards: dict[str, RewardTerm] = field(default_factory=dict)
    domain_rand: DomainRandCfg = field(default_factory=DomainRandCfg)
    obs: ObsCfg = field(default_factory=ObsCfg)
    # Training's curriculum, in env steps of the run: `DanceEnv.curriculum_scale` is 0 (the
    # body targets and the `RewardTerm.curriculum` terms off) until the first number and grows
    # linearly to 1 at the second. None: the full task throughout.
    curriculum_env_steps: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        # The robot's numbers are filled in here, so that a saved task (the policy JSON's
        # ``task``) records them (`SceneCfg` does the same for the gains).
        robot = self.scene.robot
        if self.max_tilt_rad is None:
            self.max_tilt_rad = robot.max_tilt_rad
        if self.min_base_height_m is None:
            self.min_base_height_m = robot.min_base_height_m
        if self.base_height_target_m is None:
            self.base_height_target_m = robot.standing_height_m

    @property
    def step_dt_s(self) -> float:
        return 1.0 / self.policy_hz

    @property
    def max_episode_steps(self) -> int:
        return round(self.episode_length_s * self.policy_hz)
