"""The dance task's settings: one dataclass per concern, defaults naming their source."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from quaddance.sim.scene import SceneCfg

# Table 1 of the paper: (c_f, lambda_f) pairs tried for eq. 2; "table1-5" is the chosen one.
TABLE1: dict[str, tuple[float, float]] = {
    "table1-1": (100.0, 100.0),
    "table1-2": (100.0, 10.0),
    "table1-3": (60.0, 100.0),
    "table1-4": (30.0, 100.0),
    "table1-5": (30.0, 10.0),
}


@dataclass
class RewardCfg:
    """Reward weights. Every term is multiplied by the policy step (dt) as in legged_gym,
    except `termination`, which is paid once."""

    form: str = "paper"  # "paper" = eq. 2 (exp form), "l2" = released code's -c (h - h*)^2
    c_f: float = 30.0  # eq. 2
    lambda_f: float = 10.0  # eq. 2
    c_l2: float = 30.0  # released code's L2 form
    c_r: float = -30.0  # eq. 3, rear feet (h_rl^2 + h_rr^2)
    # Ours: eq. 3 is tiny for cm-scale lifts (2 cm -> 0.012), so a linear term keeps the
    # rear feet down.
    rear_lift_l1: float = -50.0
    # Walk These Ways auxiliaries (weights from WTW's Go1 config, scaled for this task).
    torques: float = -1e-4
    joint_vel: float = -1e-4
    joint_acc: float = -2.5e-7
    action_rate: float = -0.01
    action_smoothness: float = -0.01
    collision: float = -5.0
    base_orientation: float = -1.0
    base_height: float = -10.0
    base_height_target_m: float | None = None  # None: the robot's `standing_height_m`
    joint_limits: float = -10.0
    foot_slip: float = -0.04
    # Ours: -20 per m/s slid; a foot creeping 1 cm/s costs what 0.7 mm of paw error does.
    foot_slide: float = -20.0
    base_drift: float = -1.0  # horizontal base velocity: dance in place
    yaw_rate: float = -0.5
    # Whole-body dance (DanceTaskCfg.whole_body): trunk-pose tracking in eq. 2's exp form,
    # c_body (exp(-lambda |e|) - 1) per term. base_height, base_orientation and yaw_rate
    # above are measured relative to the body target, so they equal the old terms at zero.
    c_body: float = 30.0
    lambda_body_height_per_m: float = 10.0  # 1 cm off: -2.9 / s, like a front foot 1 cm off
    lambda_body_angle_per_rad: float = 3.0  # 3 deg off: -4.4 / s
    termination: float = -200.0  # once per fall; outweighs the discounted penalties it escapes
    # Terms that training's curriculum (`DanceEnv.curriculum_scale`) brings in gradually:
    # holding the trunk to a pose and the stance feet still both make lifting a paw costly,
    # and from scratch with them at full weight the policy learnt never to lift.
    curriculum_terms: tuple[str, ...] = (
        "body_height_tracking",
        "body_tilt_tracking",
        "body_yaw_tracking",
        "foot_slide",
    )

    @classmethod
    def named(cls, name: str) -> RewardCfg:
        """`paper` (eq. 2, c_f 30, lambda_f 10), `l2`, or `table1-1` ... `table1-5`."""
        if name == "paper":
            return cls()
        if name == "l2":
            return cls(form="l2")
        if name in TABLE1:
            c_f, lam = TABLE1[name]
            return cls(c_f=c_f, lambda_f=lam)
        raise ValueError(f"unknown reward set {name!r}: use paper, l2 or one of {sorted(TABLE1)}")


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
    # roll, pitch, yaw; `quaddance.targets.BODY_COLUMNS`) enter the actor's observation, the
    # rewards track them, and a body feed-forward (quaddance.sim.body) moves all four legs
    # to hold the feet still while the trunk takes the pose.
    whole_body: bool = False
    # Terminations; None: the robot's (`RobotCfg.max_tilt_rad`, `min_base_height_m`).
    max_tilt_rad: float | None = None
    min_base_height_m: float | None = None
    scene: SceneCfg = field(default_factory=SceneCfg)
    rewards: RewardCfg = field(default_factory=RewardCfg)
    domain_rand: DomainRandCfg = field(default_factory=DomainRandCfg)
    obs: ObsCfg = field(default_factory=ObsCfg)

    def __post_init__(self) -> None:
        # The robot's numbers are filled in here, so that a saved task (the policy JSON's
        # ``task``) records them (`SceneCfg` does the same for the gains).
        robot = self.scene.robot
        if self.max_tilt_rad is None:
            self.max_tilt_rad = robot.max_tilt_rad
        if self.min_base_height_m is None:
            self.min_base_height_m = robot.min_base_height_m
        if self.rewards.base_height_target_m is None:
            self.rewards = dataclasses.replace(
                self.rewards, base_height_target_m=robot.standing_height_m
            )

    @property
    def step_dt_s(self) -> float:
        return 1.0 / self.policy_hz

    @property
    def max_episode_steps(self) -> int:
        return round(self.episode_length_s * self.policy_hz)
