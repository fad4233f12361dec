"""The policy JSON: the contract between a trained policy, playback and a real robot.

`PolicySpec` is the only code that writes (`to_json`, used by ``train.py``'s export) and
reads (`from_json`, used by `quaddance.play.policy.OnnxPolicy`) the file. Reading checks every
field: its type, that numbers are finite and in a plausible range (no value can make playback
allocate without bound), that lists have the right length, that strings are short, and that
the numbers written twice (top level and ``task``) agree. Any problem is one
`InputFileError` naming the file and the field, e.g. ``policy.json: obs.history_len: ...``.

Schema version: ``format`` = `FORMAT`; files of format 1 (whose ``task.rewards`` holds flat
weights, `quaddance.sim.tasks.FLAT_REWARDS`, instead of reward terms) are read too. A file with
another ``format`` is refused; a field that this version does not know is refused (a typo would
otherwise be ignored silently). Fields of ``task`` that a file lacks take the defaults of
`quaddance.sim.config.DanceTaskCfg` (older files predate them); the file is written back as it
was read.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import InputFileError, not_a_file
from quaddance.robots import GO1, ROBOTS, RobotCfg, get_robot
from quaddance.sim.config import SOURCES, DanceTaskCfg, ObsSlice
from quaddance.sim.records import reward_term, task_from_record

FORMAT = "quaddance-policy/2"
"""Schema version written in ``format``."""

FLAT_REWARDS_FORMAT = "quaddance-policy/1"
"""The schema before reward terms were entries: read, never written."""

MAX_JSON_BYTES = 1 << 20
"""Largest policy JSON read, bytes (the shipped one is 15 kB)."""

MAX_TEXT_CHARS = 500
"""Longest string field, characters."""

_BIG = 1e6
"""Default bound on the magnitude of a number in ``task`` without a bound of its own."""

# (lo, hi) of task fields, by dotted name; numbers without an entry lie in [-_BIG, _BIG],
# integers in [0, _BIG]. Bounds that drive allocations (envs, history, preview, variants,
# lag, iterations) are tight.
_TASK_BOUNDS: dict[str, tuple[float, float]] = {
    "num_envs": (1, 1 << 20),
    "episode_length_s": (0.01, 1e5),
    "policy_hz": (1.0, 1000.0),
    "decimation": (1, 100),
    "action_scale": (1e-6, 10.0),
    "hip_scale_factor": (0.0, 10.0),
    "max_tilt_rad": (0.0, math.pi),
    "min_base_height_m": (0.0, 1.0),
    "base_height_target_m": (0.0, 1.0),
    "curriculum_env_steps": (0, 1e15),
    "scene.timestep_s": (1e-4, 0.05),
    "scene.kp": (1e-6, 1000.0),
    "scene.kd": (0.0, 100.0),
    "scene.foot_friction": (0.0, 10.0),
    "scene.solver_iterations": (1, 1000),
    "scene.ls_iterations": (1, 1000),
    "domain_rand.num_variants": (1, 1024),
    "domain_rand.friction": (0.0, 10.0),
    "domain_rand.added_mass_kg": (-10.0, 20.0),
    "domain_rand.motor_strength": (0.0, 10.0),
    "domain_rand.joint_offset_rad": (0.0, 1.0),
    "domain_rand.max_action_lag_substeps": (0, 100),
    "domain_rand.push_interval_s": (0.01, 1e5),
    "domain_rand.push_vel_m_s": (0.0, 10.0),
    "domain_rand.init_joint_noise_rad": (0.0, 1.0),
    "domain_rand.gravity_noise": (0.0, 10.0),
    "domain_rand.gyro_noise_rad_s": (0.0, 100.0),
    "domain_rand.joint_pos_noise_rad": (0.0, 10.0),
    "domain_rand.joint_vel_noise_rad_s": (0.0, 100.0),
    "obs.preview_s": (0.0, 10.0),
    "obs.history_len": (0, 100),
}
_MAX_TUPLE = 16  # longest variable-length tuple in task (preview_s)
_REWARD_FORMS = ("paper", "l2")


@dataclass(frozen=True)
class FeedForwardSpec:
    """The front-lift feed-forward table (`quaddance.sim.feedforward`)."""

    heights_m: tuple[float, ...]
    thigh_calf_offsets_rad: tuple[tuple[float, float], ...]
    applies_to: tuple[str, ...]
    interpolation: str


@dataclass(frozen=True)
class PolicySpec:
    """A policy's JSON contract, every field checked. Units in the names; joints in
    ``joint_names`` order, feet (FL, FR, RL, RR)."""

    version: str
    joint_names: tuple[str, ...]
    feet: tuple[str, ...]
    foot_height: str
    nominal_joint_pos_rad: tuple[float, ...]
    action_scale: tuple[float, ...]
    joint_target: str
    front_feedforward: FeedForwardSpec | None
    kp: float
    kd: float
    policy_hz: float
    sim_dt_s: float
    decimation: int
    obs_layout: tuple[ObsSlice, ...]
    obs_dim: int
    obs_preview_s: tuple[float, ...]
    obs_history_len: int
    obs_normalization: str
    task: dict[str, Any]  # as in the file; `task_cfg` builds the dataclasses
    targets_max_height_m: float
    training: dict[str, Any] = field(default_factory=dict)
    # The bank's target mode; a "paper" (eq. 4) policy also has its h0, m.
    targets_mode: str = "feasible"
    targets_h0_m: float | None = None
    robot: str = GO1.name
    format: str = FORMAT

    @property
    def task_cfg(self) -> DanceTaskCfg:
        """The task settings the policy was trained with."""
        return task_from_record(self.task, get_robot(self.robot))

    # --- writing -----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The JSON object, keys in the documented order."""
        ff = self.front_feedforward
        return {
            "format": self.format,
            "version": self.version,
            "robot": self.robot,
            "joint_names": list(self.joint_names),
            "feet": list(self.feet),
            "foot_height": self.foot_height,
            "nominal_joint_pos_rad": list(self.nominal_joint_pos_rad),
            "action_scale": list(self.action_scale),
            "joint_target": self.joint_target,
            "front_feedforward": None
            if ff is None
            else {
                "heights_m": list(ff.heights_m),
                "thigh_calf_offsets_rad": [list(row) for row in ff.thigh_calf_offsets_rad],
                "applies_to": list(ff.applies_to),
                "interpolation": ff.interpolation,
            },
            "kp": self.kp,
            "kd": self.kd,
            "policy_hz": self.policy_hz,
            "sim_dt_s": self.sim_dt_s,
            "decimation": self.decimation,
            "obs": {
                # The actor's terms in order, each with the robot sensor it comes from.
                "terms": [
                    {"name": t.name, "size": t.size}
                    | ({} if t.source is None else {"source": t.source})
                    for t in self.obs_layout
                ],
                "dim": self.obs_dim,
                "preview_s": list(self.obs_preview_s),
                "history_len": self.obs_history_len,
                "normalization": self.obs_normalization,
            },
            "task": _plain(self.task),
            "targets": {"max_height_m": self.targets_max_height_m}
            | (
                {}
                if self.targets_mode == "feasible"
                else {"mode": self.targets_mode, "h0_m": self.targets_h0_m}
            ),
            "training": dict(self.training),
        }

    def to_json(self) -> str:
        """The file's text: indented JSON and a final newline."""
        return json.dumps(self.to_dict(), indent=2) + "\n"

    def save(self, path: str | Path) -> None:
        """Write the JSON to ``path``, atomically."""
        from quaddance.fileio import atomic_path

        text = self.to_json()
        with atomic_path(path) as tmp:
            tmp.write_text(text)

    # --- reading -----------------------------------------------------------------------------
    @classmethod
    def from_json(cls, text: str, path: str | Path = "policy.json") -> PolicySpec:
        """Parse and check a policy JSON; ``path`` names the file in errors."""
        try:
            obj = json.loads(text)
        except (ValueError, RecursionError) as err:  # JSONDecodeError is a ValueError
            problem = "nested too deeply" if isinstance(err, RecursionError) else str(err)
            raise InputFileError(path, f"not JSON ({problem[:200]})") from None
        return cls.from_dict(obj, path)

    @classmethod
    def load(cls, path: str | Path) -> PolicySpec:
        """Read and check the policy JSON at ``path``."""
        path = Path(path)
        if not path.is_file():
            raise not_a_file(path)
        if path.stat().st_size > MAX_JSON_BYTES:
            raise InputFileError(
                path, f"is {path.stat().st_size} bytes; a policy JSON has at most {MAX_JSON_BYTES}"
            )
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as err:
            raise InputFileError(path, f"cannot be read as UTF-8 text ({err})") from None
        return cls.from_json(text, path)

    @classmethod
    def from_dict(cls, obj: Any, path: str | Path = "policy.json") -> PolicySpec:
        """Check a parsed policy JSON object and build the spec."""
        r = _Reader(Path(path))
        obj = r.obj(obj, "", required=_TOP_KEYS)
        fmt = r.text(obj, "format")
        if fmt not in (FORMAT, FLAT_REWARDS_FORMAT):
            r.fail("format", f"{fmt!r} is not a policy format this quaddance reads ({FORMAT})")
        robot = r.text(obj, "robot")
        if robot not in ROBOTS:
            r.fail("robot", f"{robot!r}; this quaddance plays {', '.join(ROBOTS)} policies")
        cfg = ROBOTS[robot]
        joints = r.texts(obj, "joint_names", cfg.num_joints)
        if joints != cfg.joint_names:
            r.fail("joint_names", f"must be the {robot} joints in order {cfg.joint_names[0]}, ...")
        feet = r.texts(obj, "feet", len(cfg.feet))
        if feet != cfg.feet:
            r.fail("feet", f"must be {', '.join(cfg.feet)}")
        task = _read_task(r, obj, flat_rewards=fmt == FLAT_REWARDS_FORMAT)
        has_ff = task.get("front_feedforward", DanceTaskCfg.front_feedforward)
        ff = _read_feedforward(r, obj["front_feedforward"], has_ff, cfg)
        spec = cls(
            format=fmt,
            version=r.text(obj, "version", max_chars=64),
            robot=robot,
            joint_names=joints,
            feet=feet,
            foot_height=r.text(obj, "foot_height"),
            nominal_joint_pos_rad=r.numbers(
                obj, "nominal_joint_pos_rad", cfg.num_joints, -math.pi, math.pi
            ),
            action_scale=r.numbers(obj, "action_scale", cfg.num_joints, 1e-6, 10.0),
            joint_target=r.text(obj, "joint_target"),
            front_feedforward=ff,
            kp=r.number(obj, "kp", 1e-6, 1000.0),
            kd=r.number(obj, "kd", 0.0, 100.0),
            policy_hz=r.number(obj, "policy_hz", 1.0, 1000.0),
            sim_dt_s=r.number(obj, "sim_dt_s", 1e-4, 0.05),
            decimation=r.integer(obj, "decimation", 1, 100),
            **_read_obs(r, obj),
            task=task,
            **_read_targets(r, obj["targets"]),
            training=_read_training(r, obj["training"]),
        )
        _check_agreement(r, spec)
        return spec


_TOP_KEYS = (
    "format", "version", "robot", "joint_names", "feet", "foot_height", "nominal_joint_pos_rad",
    "action_scale", "joint_target", "front_feedforward", "kp", "kd", "policy_hz", "sim_dt_s",
    "decimation", "obs", "task", "targets", "training",
)  # fmt: skip


def _plain(value: Any) -> Any:
    """Tuples as lists, recursively: what JSON holds."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


class _Reader:
    """Field checks that raise `InputFileError` naming the file and the dotted field."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, name: str, problem: str) -> None:
        raise InputFileError(self.path, f"{name}: {problem}")

    def obj(
        self,
        value: Any,
        name: str,
        required: tuple[str, ...] = (),
        optional: tuple[str, ...] = (),
    ) -> dict[str, Any]:
        """A JSON object with exactly the ``required`` keys (plus any of ``optional``)."""
        where = name or "the file"
        if not isinstance(value, dict):
            self.fail(where, f"must be a JSON object, got {_json_type(value)}")
        missing = [k for k in required if k not in value]
        if missing:
            self.fail(where, f"missing field {', '.join(missing[:5])}")
        unknown = [k for k in value if k not in required and k not in optional]
        if unknown:
            self.fail(where, f"unknown field {_short(unknown[0])}")
        return value

    def text(self, obj: dict, key: str, max_chars: int = MAX_TEXT_CHARS, prefix: str = "") -> str:
        value = obj[key]
        if not isinstance(value, str):
            self.fail(prefix + key, f"must be text, got {_json_type(value)}")
        if len(value) > max_chars:
            self.fail(prefix + key, f"text of {len(value)} characters; at most {max_chars}")
        return value

    def texts(self, obj: dict, key: str, n: int, prefix: str = "") -> tuple[str, ...]:
        value = obj[key]
        if not isinstance(value, list | tuple) or len(value) != n:
            self.fail(prefix + key, f"must be a list of {n} names")
        return tuple(self.text({key: v}, key, 100, prefix) for v in value)

    def number(self, obj: dict, key: str, lo: float, hi: float, prefix: str = "") -> float:
        value = obj[key]
        # bool is an int in Python, but true is not a number in a contract.
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.fail(prefix + key, f"must be a number, got {_json_type(value)}")
        try:
            number = float(value)
        except OverflowError:  # an integer of hundreds of digits
            number = math.inf
        if not (math.isfinite(number) and lo <= number <= hi):
            self.fail(prefix + key, f"{_short(value)} is not a finite number in [{lo:g}, {hi:g}]")
        return value  # as written (20 stays 20, 20.0 stays 20.0): the file round-trips

    def flag(self, obj: dict, key: str, prefix: str = "") -> bool:
        value = obj[key]
        if not isinstance(value, bool):
            self.fail(prefix + key, f"must be true or false, got {_json_type(value)}")
        return value

    def integer(self, obj: dict, key: str, lo: int, hi: int, prefix: str = "") -> int:
        value = obj[key]
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(prefix + key, f"must be a whole number, got {_json_type(value)}")
        if not lo <= value <= hi:
            self.fail(prefix + key, f"{_short(value)} is not in [{lo}, {hi}]")
        return value

    def numbers(
        self, obj: dict, key: str, n: int | None, lo: float, hi: float, prefix: str = ""
    ) -> tuple[float, ...]:
        """A list of ``n`` numbers (any length up to `_MAX_TUPLE` if ``n`` is None)."""
        value = obj[key]
        limit = _MAX_TUPLE if n is None else n
        if not isinstance(value, list | tuple) or (
            len(value) != n if n is not None else len(value) > limit
        ):
            size = f"{n}" if n is not None else f"at most {limit}"
            self.fail(prefix + key, f"must be a list of {size} numbers")
        items = {f"{key}[{i}]": v for i, v in enumerate(value)}
        return tuple(self.number(items, k, lo, hi, prefix) for k in items)


def _json_type(value: Any) -> str:
    names = {dict: "an object", list: "a list", str: "text", bool: "true/false"}
    if value is None:
        return "null"
    return names.get(type(value), "a number" if isinstance(value, int | float) else "?")


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _read_feedforward(
    r: _Reader, value: Any, needed: bool, robot: RobotCfg
) -> FeedForwardSpec | None:
    """The table, which must have the robot's heights (`FrontLiftCfg.heights_m`)."""
    if value is None:
        if needed:
            r.fail("front_feedforward", "is missing but task.front_feedforward is true")
        return None
    keys = ("heights_m", "thigh_calf_offsets_rad", "applies_to", "interpolation")
    obj = r.obj(value, "front_feedforward", required=keys)
    p = "front_feedforward."
    heights_m = robot.front_lift.heights_m
    n = heights_m.size
    heights = r.numbers(obj, "heights_m", n, 0.0, 1.0, p)
    if not np.allclose(heights, heights_m, atol=1e-6):
        step = heights_m[1] - heights_m[0]
        r.fail(p + "heights_m", f"must be the table heights 0, {step:g}, ... {heights_m[-1]:g} m")
    rows = obj["thigh_calf_offsets_rad"]
    if not isinstance(rows, list | tuple) or len(rows) != n:
        r.fail(p + "thigh_calf_offsets_rad", f"must be a list of {n} [thigh, calf] pairs")
    table = tuple(
        r.numbers(
            {f"thigh_calf_offsets_rad[{i}]": row},
            f"thigh_calf_offsets_rad[{i}]",
            2,
            -math.pi,
            math.pi,
            p,
        )
        for i, row in enumerate(rows)
    )
    applies = obj["applies_to"]
    front = list(robot.feet[:2])
    if not isinstance(applies, list | tuple) or list(applies) not in (front, front[:1], front[1:]):
        r.fail(p + "applies_to", f"must be the front feet {', '.join(front)}")
    return FeedForwardSpec(heights, table, tuple(applies), r.text(obj, "interpolation", prefix=p))


def _read_obs(r: _Reader, obj: dict) -> dict[str, Any]:
    keys = ("dim", "preview_s", "history_len", "normalization")
    # `terms` (with sources) since the robot-measurable contract; `layout` in older files.
    obs = r.obj(obj["obs"], "obs", required=keys, optional=("terms", "layout"))
    key = "terms" if "terms" in obs else "layout"
    if ("terms" in obs) == ("layout" in obs):
        r.fail("obs", "needs exactly one of terms, layout")
    layout = obs[key]
    if not isinstance(layout, list | tuple) or not 1 <= len(layout) <= 64:
        r.fail(f"obs.{key}", "must be a list of 1 to 64 terms")
    terms = []
    for i, entry in enumerate(layout):
        name = f"obs.{key}[{i}]"
        required = ("name", "size", "source") if key == "terms" else ("name", "size")
        term = r.obj(entry, name, required=required, optional=("source",))
        source = None if "source" not in term else r.text(term, "source", 200, name + ".")
        if source is not None and not set(source.split("+")) <= set(SOURCES):
            r.fail(name + ".source", f"{_short(source)} is not one of {', '.join(SOURCES)}")
        terms.append(
            ObsSlice(
                r.text(term, "name", 100, name + "."),
                r.integer(term, "size", 1, 10_000, name + "."),
                source,
            )
        )
    return {
        "obs_layout": tuple(terms),
        "obs_dim": r.integer(obs, "dim", 1, 100_000, "obs."),
        "obs_preview_s": r.numbers(obs, "preview_s", None, 0.0, 10.0, "obs."),
        "obs_history_len": r.integer(obs, "history_len", 0, 100, "obs."),
        "obs_normalization": r.text(obs, "normalization", prefix="obs."),
    }


def _read_task(r: _Reader, obj: dict, flat_rewards: bool) -> dict[str, Any]:
    """Check ``task`` against `DanceTaskCfg`'s fields (their types from the defaults)."""
    return _read_fields(r, obj["task"], _fields(DanceTaskCfg()), "task", flat_rewards)


def _fields(default: Any) -> dict[str, Any]:
    fields = {f.name: getattr(default, f.name) for f in dataclasses.fields(default)}
    # The robot is the file's top-level ``robot`` (`task_record`), not a field of ``task``.
    return {k: v for k, v in fields.items() if not isinstance(v, RobotCfg)}


def _read_fields(
    r: _Reader, value: Any, fields: dict[str, Any], name: str, flat_rewards: bool = False
) -> dict[str, Any]:
    """An object whose keys are some of ``fields``, each value of its default's type."""
    obj = r.obj(value, name, optional=tuple(fields))
    out: dict[str, Any] = {}
    for key, value in obj.items():
        like = fields[key]
        dotted = f"{name}.{key}"
        bound = dotted.removeprefix("task.")
        if dotted == "task.rewards":
            out[key] = _read_flat_rewards(r, value) if flat_rewards else _read_rewards(r, value)
        elif dotted == "task.curriculum_env_steps":
            lo, hi = _TASK_BOUNDS[bound]
            steps = None if value is None else r.numbers(obj, key, 2, lo, hi, name + ".")
            if steps is not None and steps[0] > steps[1]:
                r.fail(dotted, "the range's low end is above its high end")
            out[key] = None if steps is None else list(steps)
        elif dataclasses.is_dataclass(like):
            out[key] = _read_fields(r, value, _fields(like), dotted)
        elif isinstance(like, bool):
            out[key] = r.flag(obj, key, name + ".")
        elif isinstance(like, str):
            text = r.text(obj, key, 100, name + ".")
            if key == "form" and text not in _REWARD_FORMS:
                r.fail(dotted, f"{text!r} is not one of {', '.join(_REWARD_FORMS)}")
            out[key] = text
        elif isinstance(like, int):
            lo, hi = _TASK_BOUNDS.get(bound, (0, _BIG))
            out[key] = r.integer(obj, key, int(lo), int(hi), name + ".")
        elif isinstance(like, float):
            lo, hi = _TASK_BOUNDS.get(bound, (-_BIG, _BIG))
            out[key] = r.number(obj, key, lo, hi, name + ".")
        elif isinstance(like, tuple) and all(isinstance(x, str) for x in like) and like:
            if not isinstance(value, list | tuple) or len(value) > 32:
                r.fail(dotted, "must be a list of at most 32 names")
            out[key] = [r.text({key: v}, key, 100, name + ".") for v in value]
            if key == "curriculum_terms":
                names = _reward_names()
                unknown = [v for v in out[key] if v not in names]
                if unknown:
                    near = difflib.get_close_matches(unknown[0], names, n=1)
                    hint = f"; did you mean {near[0]!r}?" if near else ""
                    r.fail(dotted, f"{unknown[0]!r} is no reward term{hint}")
        elif isinstance(like, tuple):
            lo, hi = _TASK_BOUNDS.get(bound, (-_BIG, _BIG))
            n = len(like) if key != "preview_s" else None
            numbers = r.numbers(obj, key, n, lo, hi, name + ".")
            if n == 2 and numbers[0] > numbers[1]:
                r.fail(dotted, "the range's low end is above its high end")
            out[key] = list(numbers)
        else:  # a field type this reader does not know: a bug in this file, not the input
            raise TypeError(f"no check for {dotted} ({type(like).__name__})")
    return out


def _reward_names() -> tuple[str, ...]:
    from quaddance.sim.tasks import dance_rewards  # torch: only once a file is checked

    return tuple(dance_rewards(whole_body=True))


def _read_flat_rewards(r: _Reader, value: Any) -> dict[str, Any]:
    """A format-1 file's flat ``task.rewards``."""
    from quaddance.sim.tasks import FLAT_REWARDS

    return _read_fields(r, value, FLAT_REWARDS, "task.rewards")


def _read_rewards(r: _Reader, value: Any) -> dict[str, Any]:
    """``task.rewards``: term name -> {fn, weight, params, curriculum, per_step}."""
    if not isinstance(value, dict) or len(value) > 64:
        r.fail("task.rewards", "must be a JSON object of at most 64 reward terms")
    out: dict[str, Any] = {}
    for term_name, entry in value.items():
        if len(term_name) > 100:
            r.fail("task.rewards", f"term name of {len(term_name)} characters")
        name = f"task.rewards.{term_name}"
        keys = ("fn", "weight", "params", "curriculum", "per_step")
        entry = r.obj(entry, name, required=keys)
        p = name + "."
        params = entry["params"]
        if not isinstance(params, dict) or len(params) > 16:
            r.fail(p + "params", "must be a JSON object of at most 16 parameters")
        for key, param in params.items():
            if isinstance(param, str):
                r.text(params, key, 100, p + "params.")
            else:
                r.number(params, key, -_BIG, _BIG, p + "params.")
        term = {
            "fn": r.text(entry, "fn", 100, p),
            "weight": r.number(entry, "weight", -_BIG, _BIG, p),
            "params": dict(params),
            "curriculum": r.flag(entry, "curriculum", p),
            "per_step": r.flag(entry, "per_step", p),
        }
        try:
            reward_term(term)
        except ValueError as err:
            r.fail(p + "fn", str(err))
        out[term_name] = term
    return out


def _read_targets(r: _Reader, value: Any) -> dict[str, Any]:
    """The targets the policy trained on: the feasible range, and an eq. 4 bank's mode and h0."""
    obj = r.obj(value, "targets", required=("max_height_m",), optional=("mode", "h0_m"))
    out: dict[str, Any] = {
        # 0: a bank of all-zero targets (tests) trains a policy that stands
        "targets_max_height_m": r.number(obj, "max_height_m", 0.0, 1.0, "targets."),
    }
    if "mode" in obj or "h0_m" in obj:
        r.obj(obj, "targets", required=("max_height_m", "mode", "h0_m"))
        if obj["mode"] != "paper":
            r.fail(
                "targets.mode", f"{_short(obj['mode'])}; a policy's targets are feasible or paper"
            )
        out["targets_mode"] = "paper"
        out["targets_h0_m"] = r.number(obj, "h0_m", 1e-3, 100.0, "targets.")
    return out


def _read_training(r: _Reader, value: Any) -> dict[str, Any]:
    """Training notes: a flat object of short texts, numbers and nulls (shown, never used)."""
    if not isinstance(value, dict) or len(value) > 32:
        r.fail("training", "must be a JSON object of at most 32 fields")
    for key, item in value.items():
        if len(key) > 64:
            r.fail("training", f"field name of {len(key)} characters")
        if item is None or isinstance(item, bool):
            continue
        if isinstance(item, str):
            r.text(value, key, 200, "training.")
        elif isinstance(item, int | float):
            r.number(value, key, -1e15, 1e15, "training.")
        else:
            r.fail(
                f"training.{_short(key)}", f"must be text, a number or null, got {_json_type(item)}"
            )
    return dict(value)


def _check_agreement(r: _Reader, spec: PolicySpec) -> None:
    """The numbers written at the top level and in ``task`` must agree."""
    cfg = spec.task_cfg
    pairs = [
        ("kp", spec.kp, "task.scene.kp", cfg.scene.kp),
        ("kd", spec.kd, "task.scene.kd", cfg.scene.kd),
        ("policy_hz", spec.policy_hz, "task.policy_hz", cfg.policy_hz),
        ("sim_dt_s", spec.sim_dt_s, "task.scene.timestep_s", cfg.scene.timestep_s),
        ("decimation", spec.decimation, "task.decimation", cfg.decimation),
    ]
    for name, value, other, other_value in pairs:
        if not math.isclose(value, other_value, rel_tol=1e-9):
            r.fail(name, f"{value:g} disagrees with {other} = {other_value:g}")
    if not math.isclose(cfg.scene.timestep_s * cfg.decimation * cfg.policy_hz, 1.0, rel_tol=1e-6):
        r.fail("policy_hz", "policy_hz x sim_dt_s x decimation must be 1")
    observed = [
        ("obs.history_len", spec.obs_history_len, "task.obs.history_len", cfg.obs.history_len),
        ("obs.preview_s", spec.obs_preview_s, "task.obs.preview_s", tuple(cfg.obs.preview_s)),
    ]
    for name, value, other, other_value in observed:
        if value != other_value:
            r.fail(name, f"disagrees with {other}: the policy was trained with other observations")
    # The terms must be the ones this code builds (sim/observations.py), in the same order.
    from quaddance.sim.observations import ActorObservation  # torch: once a file is checked

    ours = [(t.name, t.size) for t in ActorObservation(cfg, 1).layout]
    theirs = [(t.name, t.size) for t in spec.obs_layout]
    if theirs != ours:
        first = next(
            (i for i, (a, b) in enumerate(zip(theirs, ours, strict=False)) if a != b),
            min(len(theirs), len(ours)),
        )
        r.fail(f"obs.terms[{first}]", "is not the actor term this version of quaddance builds")
    if sum(size for _, size in theirs) != spec.obs_dim:
        r.fail("obs.dim", f"{spec.obs_dim} is not the sum of the term sizes")
