"""Typed, validated schema of ``params.yaml``.

Every stage loads the file through :func:`load_params` before any compute: an unknown key, a missing one,
a wrong type or an impossible value raises :class:`ParamsError` naming the key and the value.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from pydantic.fields import FieldInfo

from lfdt.seeding import MAX_EPISODES

PosFloat = Annotated[float, Field(gt=0)]
NonNegFloat = Annotated[float, Field(ge=0)]
MAX_COUNT = 2**31 - 1
"""Largest size or count a param may take: numpy, torch and MuJoCo index with 32-bit integers, and a larger value
(``1e29`` written as an integer) would fail a stage after DVC removed its outputs, not in preflight."""
PosInt = Annotated[int, Field(gt=0, le=MAX_COUNT)]
Count = Annotated[int, Field(ge=0, le=MAX_COUNT)]
Episodes = Annotated[int, Field(gt=0, le=MAX_EPISODES)]
"""A count of episodes that each take a start state of their own: a seed has :data:`lfdt.seeding.MAX_EPISODES` of
them per purpose, and a larger count would fail its stage at the first start state past them."""
Fraction = Annotated[float, Field(gt=0, lt=1)]
XY = Annotated[list[float], Field(min_length=2, max_length=2)]
PosXY = Annotated[list[PosFloat], Field(min_length=2, max_length=2)]


class Strict(BaseModel):
    """Base: unknown keys are errors, field docstrings become descriptions."""

    model_config = ConfigDict(extra="forbid", use_attribute_docstrings=True, frozen=True, strict=True,
                              allow_inf_nan=False)


class ArmConfig(Strict):
    """A planar serial arm: links, motors and passive joint dynamics."""

    links: list[PosFloat] = Field(min_length=2, max_length=6)
    """Link lengths from base to tip, m."""
    gears: list[PosFloat]
    """Motor gear per joint: torque (N m) at a command of 1."""
    damping: list[PosFloat]
    """Viscous joint damping per joint, N m s/rad (sets the arm's top speed: gear / damping)."""
    armature: NonNegFloat = 0.005
    """Rotor inertia added to every joint, kg m^2."""
    joint_range: list[PosFloat]
    """Symmetric joint limit per joint, rad."""
    radius: PosFloat = 0.012
    """Capsule radius of the links, m."""
    tip_radius: PosFloat = 0.012
    """Radius of the sphere at the end effector (the 'hand'), m."""

    @model_validator(mode="after")
    def _lengths(self) -> ArmConfig:
        n = len(self.links)
        for name in ("gears", "damping", "joint_range"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name} has {len(getattr(self, name))} entries but links has {n}")
        return self


class BoxConfig(Strict):
    """The pushed box."""

    size: PosXY = [0.12, 0.08]
    """Width (x) and depth (y), m."""
    mass: PosFloat = 0.3
    """Mass, kg."""
    slide_damping: PosFloat = 3.0
    """Viscous damping of the planar slide joints, N s/m (makes the task quasi-static)."""
    yaw_damping: PosFloat = 0.01
    """Viscous damping of the yaw hinge, N m s/rad."""
    start: XY = [0.0, 0.22]
    """Mean start position of the box centre, m."""
    goal: XY = [0.0, 0.34]
    """Goal position of the box centre, m."""
    start_noise_xy: NonNegFloat = 0.02
    """Half-width of the uniform noise on the start position, m."""
    start_noise_yaw: NonNegFloat = 0.25
    """Half-width of the uniform noise on the start yaw, rad."""


class SuccessConfig(Strict):
    """Success: all three conditions at once."""

    distance: PosFloat = 0.03
    """Box centre within this distance of the goal, m."""
    yaw: PosFloat = 0.15
    """Absolute box yaw below this, rad."""
    speed: PosFloat = 0.02
    """Box speed below this (at rest), m/s."""
    path_yaw_margin: PosFloat = 0.05
    """Path rule, reported beside the end-state rule: the box's |yaw| never exceeds max(|start yaw|, yaw) plus this
    along the episode, rad (the paper's task asks to push 'while avoiding the rotation of the box')."""


class RewardConfig(Strict):
    """Dense reward for the SAC experts: -w_box d_box - w_yaw |yaw| - w_contact sum d_ci - w_action |a|^2
    - w_action_rate |a - a_prev|^2."""

    w_box: NonNegFloat = 10.0
    """Weight of the box-to-goal distance, 1/m."""
    w_yaw: NonNegFloat = 2.0
    """Weight of the absolute box yaw, 1/rad."""
    w_contact: NonNegFloat = 20.0
    """Weight of the end-effector-to-contact-point distances, 1/m (at 5 the SAC human of the programmed-robot protocol
    hovered and poked, touching the box in 25-29 % of the frames; at 20 it pushes along, 62-67 %)."""
    w_action: NonNegFloat = 0.01
    """Weight of the squared action norm."""
    w_action_rate: NonNegFloat = 1.0
    """Weight of the squared change of the command from one control step to the next (a person moves smoothly:
    without it the SAC human's commands changed by 0.22 per step on average, and its translated motion was hard to
    clone)."""
    success_bonus: NonNegFloat = 10.0
    """Bonus on success (the episode then ends)."""


class EnvConfig(Strict):
    """The simulated 2D dual-arm box push (all three domains)."""

    JOINTS: ClassVar[dict[str, int]] = {"robot": 3, "human": 4}
    """Joints of each robot and of the human stand-in: the box push's column layout
    (:mod:`lfdt.tasks.box_push.columns`) is built from these, so ``links`` must match them."""

    timestep: PosFloat = 0.005
    """Physics time step, s."""
    frame_skip: PosInt = 10
    """Physics steps per control step (0.05 s at the defaults: 20 Hz control)."""
    max_episode_steps: PosInt = 60
    """Control steps before an episode is truncated."""
    base_x: PosFloat = 0.15
    """Arm bases stand at x = -base_x (slot 1) and +base_x (slot 2), y = 0, m."""
    contact_x: PosFloat = 0.035
    """Lateral offset of each arm's contact point on the box's rear face from the box centre, m."""
    start_gap: NonNegFloat = 0.01
    """Gap between end effector surface and box rear face in the start pose, m."""
    joint_noise: NonNegFloat = 0.05
    """Half-width of the uniform noise on the start joint angles, rad."""
    friction: PosFloat = 0.5
    """Sliding friction between arms and box."""
    robot: ArmConfig = ArmConfig(
        links=[0.15, 0.12, 0.10], gears=[1.2, 0.8, 0.4], damping=[1.0, 0.8, 0.5],
        joint_range=[2.9, 2.9, 2.9])
    """Robot1 and Robot2 (identical 3-link arms)."""
    human: ArmConfig = ArmConfig(
        links=[0.11, 0.09, 0.07, 0.06], gears=[2.0, 1.4, 0.9, 0.45], damping=[0.8, 0.6, 0.4, 0.2],
        joint_range=[2.6, 2.6, 2.0, 1.5], armature=0.002, tip_radius=0.02)
    """The human stand-in: 4 shorter links, stronger and faster motors, smaller joint ranges, a rounder hand."""
    box: BoxConfig = BoxConfig()
    """The pushed box."""
    success: SuccessConfig = SuccessConfig()
    """Success thresholds."""
    reward: RewardConfig = RewardConfig()
    """Expert reward."""

    @model_validator(mode="after")
    def _joint_counts(self) -> EnvConfig:
        # every data file, network and translator is laid out for these joint counts (lfdt.tasks.box_push.columns)
        for name, want in self.JOINTS.items():
            if len(getattr(self, name).links) != want:
                raise ValueError(f"{name}.links has {len(getattr(self, name).links)} links; the state layout "
                                 f"(lfdt/config.py EnvConfig.JOINTS) is built for {want}")
        return self


class ExpertsConfig(Strict):
    """SAC experts in domain X (one policy controls both arms of a pairing)."""

    total_timesteps: PosInt = 200_000
    """Environment steps of SAC training per pairing."""
    n_envs: PosInt = 4
    """Parallel environments (one gradient step per vectorised step: n_envs env steps per gradient step)."""
    net_arch: list[PosInt] = Field(default=[256, 256], min_length=1)
    """Hidden layers of the actor and of each critic."""
    learning_rate: PosFloat = 3e-4
    """Adam learning rate."""
    batch_size: PosInt = 256
    """Minibatch size of a gradient step."""
    buffer_size: PosInt = 300_000
    """Replay buffer capacity, transitions."""
    learning_starts: Count = 5_000
    """Environment steps of random actions before learning starts."""
    gamma: Fraction = 0.97
    """Discount factor."""
    gradient_steps: PosInt = 1
    """Gradient steps per vectorised environment step."""
    checkpoint_every: PosInt = 25_000
    """Environment steps between resumable checkpoints (model and replay buffer)."""
    log_every: PosInt = 5_000
    """Environment steps between learning-curve points sent to MLflow."""
    eval_episodes: Episodes = 100
    """Episodes with fresh seeds used to measure each expert's success rate."""
    torch_threads: PosInt = 1
    """Torch CPU threads (1 is fastest for these small networks and lets two stages share 2 cores)."""
    seed: Annotated[int, Field(ge=0, le=9)] = 0
    """Training seed."""


class RandomConfig(Strict):
    """Random-motion data: uniform torque commands, each held for a random number of control steps."""

    transitions: PosInt = 400_000
    """Transitions per domain (the paper: 0.4M per domain)."""
    episode_steps: PosInt = 100
    """Control steps per random-motion episode (episodes start from the task's start distribution)."""
    hold_min: PosInt = 1
    """Fewest control steps a random command is held."""
    hold_max: PosInt = 5
    """Most control steps a random command is held."""
    box_y_spread: NonNegFloat = 0.12
    """Episodes start with the box a further U[0, box_y_spread] m along the push direction, covering the path
    to the goal (0 = the task's own start distribution)."""
    amplitude: Annotated[float, Field(gt=0, le=1)] = 1.0
    """Commands are uniform in [-amplitude, amplitude] per joint."""
    push_fraction: Annotated[float, Field(ge=0, le=1)] = 0.5
    """Share of the episodes whose arms push: each arm's end heads along the push direction at its own random speed,
    start and distance, with held random commands of ``push_noise`` on top (so F sees two arms pushing the box, in
    and out of step); the rest are the uniform commands above. 0 = none (the paper's plain random motion). With 0.5,
    F's error across the box on two-arm pushes fell from 0.98 to 0.30 of predicting no change and LfDT on the
    development seeds rose from 64 to 81-85 % (docs/experiments.md, issue 37)."""
    push_noise: Annotated[float, Field(ge=0, le=1)] = 0.3
    """Amplitude of the held uniform commands added to a pushing episode's commands."""
    threads: PosInt = 2
    """Threads of the batched MuJoCo rollout."""
    episodes_per_batch: PosInt = 250
    """Episodes simulated per batched rollout call (bounds memory)."""
    seed: Annotated[int, Field(ge=0, le=9)] = 0
    """Collection seed."""

    @model_validator(mode="after")
    def _hold(self) -> RandomConfig:
        if self.hold_min > self.hold_max:
            raise ValueError(f"hold_min ({self.hold_min}) > hold_max ({self.hold_max})")
        _check_episodes(self.transitions, self.episode_steps, "transitions", "episode_steps")
        return self


def _check_episodes(samples: int, steps: int, samples_key: str, steps_key: str) -> None:
    """``samples`` recorded in episodes of ``steps`` take at most :data:`MAX_EPISODES` start states."""
    episodes = -(-samples // steps)
    if episodes > MAX_EPISODES:
        raise ValueError(f"{samples_key} = {samples} in episodes of {steps_key} = {steps} are {episodes} episodes, "
                         f"but a seed has {MAX_EPISODES} start states")


TWIN_ATTEMPTS_PER_DEMO = 20
"""The twin's scripted demonstrations: takes tried per demonstration kept (at least 200 in all) before its collection
gives up."""


class RobotProgramConfig(Strict):
    """One robot's push program, written for that robot alone (as an operator programs each take separately)."""

    speed: PosFloat = 0.08
    """Nominal end-effector push speed along the push direction (+y), m/s."""
    delay: NonNegFloat = 0.0
    """Nominal time before the push starts, s."""
    end_offset: float = 0.0
    """Added to the push length (the box's start-to-goal distance, measured before the take), m."""


class ProgramVariation(Strict):
    """Per-demonstration variation of a programmed robot (each take draws it once, before the episode)."""

    speed_scale: Annotated[list[PosFloat], Field(min_length=2, max_length=2)] = [0.8, 1.2]
    """The take's speed is the program's times U[speed_scale[0], speed_scale[1]]."""
    delay: NonNegFloat = 0.2
    """The take starts U[0, delay] s later than the program's own delay."""
    lateral_offset: NonNegFloat = 0.01
    """The held lateral end position is the start position plus U[-lateral_offset, lateral_offset], m."""
    end_offset: NonNegFloat = 0.005
    """The take's end point moves by U[-end_offset, end_offset] along the push direction, m."""
    action_noise: NonNegFloat = 0.02
    """Standard deviation of Gaussian noise added to every torque command (normalised units)."""

    @model_validator(mode="after")
    def _ordered(self) -> ProgramVariation:
        if self.speed_scale[0] > self.speed_scale[1]:
            raise ValueError(f"speed_scale {self.speed_scale} must be [low, high]")
        return self


class ProgramConfig(Strict):
    """The robots' programmed motions in demonstrations of the 'programmed_robot' protocol (paper §IV-E: the
    robotic arm replays a motion programmed in advance; the human adapts)."""

    r1: RobotProgramConfig = RobotProgramConfig(speed=0.07)
    """Robot1's program (used in R1H demonstrations)."""
    r2: RobotProgramConfig = RobotProgramConfig(speed=0.10)
    """Robot2's program (used in HR2 demonstrations)."""
    variation: ProgramVariation = ProgramVariation()
    """What changes from one take to the next."""
    lateral_gain: PosFloat = 2.0
    """Gain holding the end effector at the take's lateral position, 1/s."""
    approach_gain: PosFloat = 4.0
    """Gain of the final approach to the end point (the push slows down within speed / gain of it), 1/s."""


class DemosConfig(Strict):
    """Expert demonstrations in domain X."""

    protocol: Literal["programmed_robot", "joint_expert"] = "programmed_robot"
    """Who acts in a demonstration: 'programmed_robot' (the paper's: the robot replays a programmed motion, an SAC
    human stand-in adapts to it) or 'joint_expert' (one SAC policy drives both arms)."""
    program: ProgramConfig = ProgramConfig()
    """The robots' programs ('programmed_robot' protocol)."""

    per_pairing: PosInt = 200
    """Successful demonstrations kept per pairing."""
    max_attempts: Episodes = 2_000
    """Give up (and fail the stage) after this many attempts per pairing."""
    deterministic: bool = True
    """Use the expert's mean action (True) or sample from it (False)."""
    success_only: bool = True
    """Keep only successful episodes (False keeps every attempt: for smoke runs with untrained experts)."""
    seed: Annotated[int, Field(ge=0, le=9)] = 0
    """Collection seed."""

    @model_validator(mode="after")
    def _attempts(self) -> DemosConfig:
        # the stage gives up after max_attempts attempts: it could never keep more demonstrations than that
        if self.per_pairing > self.max_attempts:
            raise ValueError(f"per_pairing ({self.per_pairing}) is more than max_attempts ({self.max_attempts}): "
                             "collect_demos would give up before it has them")
        return self


class DynamicsConfig(Strict):
    """Forward and inverse dynamics models of domain Y (paper: 4 FC layers of 256, leaky ReLU, Adam 3e-4)."""

    hidden: list[PosInt] = Field(default=[256, 256, 256], min_length=1)
    """Hidden layers ('4 fully connected layers' = 3 hidden + the output layer)."""
    learning_rate: PosFloat = 3e-4
    """Adam learning rate."""
    batch_size: PosInt = 128
    """Minibatch size (the paper uses 32; 128 learns the box's contact dynamics markedly better in the same time)."""
    iterations: PosInt = 40_000
    """Gradient steps of each model."""
    val_fraction: Fraction = 0.1
    """Fraction of random-motion episodes held out."""
    std_floor: PosFloat = 1e-2
    """Floor on the per-dimension standard deviation used for normalisation."""
    eval_every: PosInt = 2_000
    """Iterations between held-out evaluations (learning curves)."""
    torch_threads: PosInt = 1
    """Torch CPU threads."""
    seed: Annotated[int, Field(ge=0, le=9)] = 0
    """Initialisation, minibatch and split seed."""
    action_scale: Literal["raw", "normalised"] = "raw"
    """Units of the actions F takes and F^-1 predicts: as recorded ('raw': the box push's torques in [-1, 1]), or
    scaled by the random motion's action mean and standard deviation ('normalised': the twin's targets are a few
    millimetres, which F^-1 learnt in metres only to about 1 mm; README, twin development)."""


class GridConfig(Strict):
    """Values the matrix stages of the second half run over (the methods are the records of :mod:`lfdt.methods`)."""

    translator_methods: list[str] = Field(default=["lfdt", "lfdt_no_dyn", "lfdt_no_id"], min_length=1)
    """Translator variants: lfdt (all losses), lfdt_no_dyn (lambda_dyn = 0), lfdt_no_id (lambda_id = 0)."""
    bc_methods: list[str] = Field(default=["bc_no_translation", "lfdt", "lfdt_no_dyn", "lfdt_no_id", "lfdt_track"],
                                  min_length=1)
    """Rows of Table I: BC without translation, BC on each translator's output, and lfdt_track (ours: the lfdt
    translator's demonstrations re-executed in Y)."""
    demos: list[PosInt] = Field(default=[50, 100, 200], min_length=1)
    """Demonstrations per pairing given to translation and BC (a subset drawn per seed)."""
    seeds: list[Annotated[int, Field(ge=0, le=999)]] = Field(default=list(range(100, 110)), min_length=1)
    """Training seeds (translator, BC, demo subset), each a whole run of the matrix stages. Ten seeds that no
    development run used (those used 0-9, 20-49; docs/experiments.md), fixed before any of their results existed."""
    workers: Annotated[int, Field(ge=1, le=64)] = 2
    """Processes a matrix stage runs its seeds in, side by side, each training its share of the seeds as one stacked
    model (2 uses both cores of a laptop-class CPU; a seed's result does not depend on it)."""

    @model_validator(mode="after")
    def _consistent(self) -> GridConfig:
        from lfdt import methods

        for name in ("translator_methods", "bc_methods", "demos", "seeds"):
            values = getattr(self, name)
            if len(set(values)) != len(values):
                raise ValueError(f"{name} has duplicates: {values}")
        bad = [m for m in self.translator_methods if m not in methods.translator_methods()]
        if bad:
            raise ValueError(f"translator_methods {bad} are not translator methods; expected some of "
                             f"{methods.translator_methods()}")
        bad = [m for m in self.bc_methods if m not in methods.METHODS]
        if bad:
            raise ValueError(f"bc_methods {bad} are unknown; expected some of {list(methods.METHODS)}")
        missing = sorted({methods.METHODS[m].translator for m in self.bc_methods} - {None}
                         - set(self.translator_methods))
        if missing:
            raise ValueError(f"bc_methods need the translators {missing}: add them to translator_methods")
        return self


class TranslatorConfig(Strict):
    """Generator G, discriminator D and the loss of eq. 6 (paper: 3 FC layers of 256, leaky ReLU, Adam 3e-4,
    batch 32)."""

    lambda_adv: NonNegFloat = 1.0
    """Weight of the adversarial loss L_adv (eq. 1)."""
    lambda_dyn: NonNegFloat = 3.0
    """Weight of the dynamics-consistency loss L_dyn (eq. 2); lfdt_no_dyn sets it to 0. The box push's 3, lambda_id
    30 and learning rate 1e-3 (before: 10 / 100 / 3e-4): the budgeted search's weights on the paper's loss, confirmed
    on development seeds it did not use (docs/experiments.md, search and confirm blocks, 'side0')."""
    lambda_id: NonNegFloat = 30.0
    """Weight of the partial identity loss L_id (eq. 5); lfdt_no_id sets it to 0 (the box push's 30: see lambda_dyn)."""
    lambda_hand: NonNegFloat = 0.0
    """Weight of a hand loss: the missing robot's end position against the human's hand position (the same world
    frame, as in the paper's real-robot state), in Y's normalised units. Not in the paper (0 = off)."""
    lambda_side: NonNegFloat = 0.0
    """Weight of a sideways term: where the missing robot's end is across the object, in the object's own frame,
    against where the human's hand is (Y's normalised units). Only the across coordinate: a hand and a robot's end
    touch the rear face at different depths but at the same place along it. Not in the paper (0 = off)."""
    hidden: list[PosInt] = Field(default=[256, 256], min_length=1)
    """Hidden layers of G and D ('3 fully connected layers' = 2 hidden + output)."""
    learning_rate: PosFloat = 1e-3
    """Adam learning rate of G and D (the paper: 3e-4; the box push's 1e-3: see lambda_dyn)."""
    batch_size: Annotated[int, Field(ge=4)] = 128
    """Minibatch: half demonstration transitions, half X random transitions, both pairings in each half (the paper:
    32; 128 made translations that BC could use more often on the development start states: README)."""
    iterations: PosInt = 6_000
    """Gradient steps of G (and of D)."""
    lr_decay: Literal["none", "cosine", "linear"] = "none"
    """Learning rate of G and D over the iterations: constant ('none', the paper's Adam), or decayed to 0 along a
    half cosine or a straight line, so that the last iterates change little."""
    object: Literal["translate", "correct", "copy"] = "copy"
    """How y_hat^O is made: G's output ('translate', as in the paper), G's correction added to x^O ('correct'), or
    x^O itself ('copy': the same object, seen alike in both domains). The robot's columns never have such a
    shortcut: the partial identity loss stays their only tie to x^Ri."""
    kinematics: Literal["learned", "forward"] = "forward"
    """What of y_hat G outputs for the robots. 'learned' (the paper): every column. 'forward': Y's arm model is
    known, so G outputs joint angles; a translated arm's end position is the forward kinematics of its joint angles
    and its joint velocity the change of its joint angles over the control step (zero at an episode's start). On
    the development start states, with the default demonstrations and translator seeds 0 and 1, BC on 'learned'
    translations succeeded 0.8-1.7 %, on 'forward' ones 67-91 % (README, development log steps 12-13; other
    translator seeds do worse, steps 15-22); tasks whose states hold no joints (the twin) need 'learned'."""
    hand_skip: bool = False
    """G outputs the missing robot's end position as a correction added to the human's hand position (both are
    positions in the same world frame, as in the paper's real-robot state)."""
    hand_offset: bool = False
    """The hand loss compares the missing robot's end with the hand plus a constant offset per pairing, learnt with
    G, so that the dynamics set it (a hand and a robot's end do not touch the object at the same point; the paper
    expects translation to account for such differences). False: with the hand itself."""
    gan_loss: Literal["bce", "lsgan"] = "bce"
    """Non-saturating BCE-with-logits as in eq. 1, or least squares."""
    history_size: Count = 0
    """Pool of past generated states shown to D (0 = none; Cycle-Dynamics uses 128)."""
    d_lr_scale: PosFloat = 1.0
    """D's learning rate is this times G's (1 = the paper's one learning rate; Cycle-Dynamics: 10)."""
    disc_input: Literal["state", "robots"] = "robots"
    """What D sees of a state: all of it ('state', the paper), or only the robots' columns, those G makes
    ('robots': G cannot change the copied box, through which D told translated demonstrations apart). With adv_on
    'random', LfDT rose from 40-50 % to 64-76 % on three blocks of development seeds (README, steps 29-31b)."""
    adv_on: Literal["all", "random"] = "random"
    """Which translated transitions L_adv and D see: all of the batch ('all', the paper: demonstrations and X random
    motion) or X random motion only ('random': Y has random motion but no demonstrations to compare with; README,
    steps 30-31b)."""
    dyn_object_weight: NonNegFloat = 1.0
    """Weight of the object's columns in L_dyn relative to the robots' (1 = the paper's plain mean over the whole
    state)."""
    dyn_scale: Literal["delta", "state"] = "delta"
    """Units of L_dyn: normalised one-step changes ('delta') or normalised states ('state')."""
    dyn_norm: Literal["l2", "l1"] = "l2"
    """L_dyn's per-column error: squared ('l2', eq. 2) or absolute ('l1', Cycle-Dynamics)."""
    labels: Literal["inverse", "recorded_robot"] = "inverse"
    """BC action labels: F^-1(y_hat_t, y_hat_t+1) for both arms, or keep the recorded action of the real robot."""
    restarts: PosInt = 1
    """Translators trained on the same demonstrations from other initialisations (seeds seed + 1000 r); the
    translation is the mean of their normalised outputs (1 = the paper's single translator; README, step 28)."""
    holdout_fraction: Annotated[float, Field(ge=0, lt=1)] = 0.1
    """Fraction of each pairing's demonstrations (whole episodes) G never trains on; G keeps its parameters of the
    lowest translation loss on them (0 = keep the last iterate)."""
    select_every: PosInt = 500
    """Iterations between measurements of the held-out translation loss."""
    log_every: PosInt = 200
    """Iterations between diagnostics sent to MLflow."""
    torch_threads: PosInt = 1
    """Torch CPU threads."""

    @property
    def steps(self) -> int:
        """Training iterations of one seed, all its restarts together (what a stage's progress bar counts)."""
        return self.iterations * self.restarts


class TrackConfig(Strict):
    """Closed-loop re-execution of the translated demonstrations in Y (the ``lfdt_track`` row, our extension)."""

    controller: Literal["jacobian", "inverse"] = "jacobian"
    """'jacobian': resolved-rate control of both ends towards their next translated positions; 'inverse':
    a_t = F^-1(y_t, y_hat_t+1) from the state actually reached."""
    gain: Annotated[float, Field(gt=0, le=1)] = 1.0
    """Share of the distance to the next translated end position the Jacobian controller asks for in one step."""
    settle_steps: Count = 10
    """Control steps after the demonstration's last target, holding it, for the box to come to rest."""
    success_only: bool = True
    """Keep only the executions that solve the task (False keeps every execution: for smoke runs with untrained
    models)."""


class BCConfig(Strict):
    """Behaviour cloning (paper: 90/10 split, keep the checkpoint with the lowest validation loss)."""

    hidden: list[PosInt] = Field(default=[256, 256], min_length=1)
    """Hidden layers of the policy."""
    learning_rate: PosFloat = 3e-4
    """Adam learning rate."""
    batch_size: PosInt = 32
    """Minibatch size."""
    iterations: PosInt = 8_000
    """Gradient steps."""
    val_fraction: Fraction = 0.1
    """Fraction of demonstrations (whole episodes) held out for checkpoint selection."""
    eval_every: PosInt = 200
    """Iterations between validation losses (a checkpoint is kept when the loss improves)."""
    input_noise: NonNegFloat = 0.0
    """Standard deviation of Gaussian noise added to the normalised training inputs (0 = none)."""
    recovery_copies: Annotated[int, Field(ge=0, le=16)] = 0
    """Copies of each translated (or re-executed) transition with its state perturbed and its action relabelled by
    F^-1 towards the demonstration's next state, so that BC also learns how to get back onto a demonstration (0 = the
    paper's plain BC; BC without translation has no F^-1 of its domain and ignores it)."""
    recovery_noise: PosFloat = 0.1
    """Standard deviation of the perturbation of recovery copies, in Y's normalised state units."""
    torch_threads: PosInt = 1
    """Torch CPU threads."""


class EvaluationConfig(Strict):
    """Trials in domain Y from fixed start states (the evaluation seed block, never used in training)."""

    trials: Episodes = 200
    """Trials per (method, demos, seed), from the same start states for every configuration (the paper: 20; Table I
    also shows the first 20)."""
    start_states: Literal["evaluation", "development"] = "evaluation"
    """Seed block of the start states: 'evaluation' (the reported Table I) or 'development' (a disjoint block for
    choosing settings, e.g. `dvc exp run -S evaluation.start_states=development`)."""
    videos: Count = 2
    """Rollout videos (mp4) of the first trials of each config."""
    video_size: Annotated[int, Field(ge=64, le=640)] = 240
    """Video frame width and height, pixels."""


class TwinParams(Strict):
    """The real-robot tasks (paper §IV-E) on the MuJoCo twin (backend 'sim') or from recordings made on the
    robots with ``python -m lfdt.robot`` (backend 'real'), with the paper's real-experiment sizes."""

    tasks: list[str] = Field(default=["block_push", "peg_insertion"], min_length=1)
    """The real-robot tasks to run (lfdt/tasks; with the robots, only those you recorded)."""
    backend: Literal["sim", "real"] = "sim"
    """'sim': generate data and evaluate in the twin; 'real': read recordings and deployment logs from real_dir."""
    real_dir: str = "data/real"
    """Where `python -m lfdt.robot record-random/record-demos/deploy` wrote their files (backend 'real'; a DVC
    dependency of the twin stages, so new recordings or trials rerun what they feed)."""
    random_samples: PosInt = 3_300
    """Random-motion samples per domain (the paper: 3300)."""
    random_episode_steps: PosInt = 30
    """Control steps per random-motion episode."""
    random_hold_max: PosInt = 3
    """A random target is held for 1..random_hold_max control steps."""
    demos_per_pairing: PosInt = 10
    """Successful demonstrations per pairing (the paper: 10 + 10)."""
    trials: Episodes = 50
    """Evaluation trials per task, method and seed, from the same start states (the paper: 10 real trials, too few
    to tell 80 % from 100 %)."""
    videos: Count = 1
    """Rollout videos per task and method."""
    seeds: list[Annotated[int, Field(ge=0, le=9)]] = Field(default=[3, 4, 5], min_length=1)
    """Seeds of the twin's data, dynamics, translator and BC, one whole run each (backend 'real': the robots'
    recordings are one set, so the seeds differ only in training). Not 0-2, the seeds of development runs."""
    dynamics: DynamicsConfig = DynamicsConfig(batch_size=32, iterations=8_000, eval_every=1_000,
                                              action_scale="normalised")
    """Dynamics models of the twin's domain Y, with actions at unit scale (F^-1's error on the real robot's recorded
    demonstration actions fell from 0.9-1.2 to 0.4-0.6 mm; README, twin development)."""
    translator: TranslatorConfig = TranslatorConfig(iterations=4_000, kinematics="learned", batch_size=32,
                                                    lambda_hand=100.0, disc_input="state", adv_on="all",
                                                    # written out: the box push's translator defaults are not the twin's
                                                    lambda_dyn=10.0, lambda_id=100.0, lambda_side=0.0,
                                                    learning_rate=3e-4)
    """Translator of the twin (the same loss; end positions instead of joint states), with lambda_hand 100 (not in
    the paper; it ties the missing robot's end to the human's hand): on the development start states LfDT in peg
    insertion went from 35 to 82 % (twin seeds 0-2) and from 40 to 94 % (6-8) against lambda_hand 1, in block push
    from 30 to 53 % and from 23 to 29 % (README, twin development). D as in the paper (disc_input 'state', adv_on
    'all'): the box push's D lowered the twin's block push (README). A learnt hand offset (hand_offset) helped block
    push a little and broke peg insertion (README)."""
    task_translator: dict[str, dict[str, Any]] = Field(default={"block_push": {"hand_offset": True}})
    """Changes to translator for one task (task -> translator fields): block push learns its hand offset (its
    LfDT rose from 78 to 83 % on twin seeds 0-2 and from 51 to 72 % on 6-8), peg insertion does not (93 -> 27 %)
    (README, twin development)."""
    bc: BCConfig = BCConfig(iterations=4_000)
    """Behaviour cloning on the twin."""
    task_bc: dict[str, dict[str, Any]] = Field(default={"block_push": {"input_noise": 0.1}})
    """Changes to bc for one task (task -> bc fields), as task_translator does for the translator: block push's BC
    (both methods) trains on inputs with Gaussian noise, which lifted its LfDT from 75.5 to 94.7 % on unseen
    development trials of twin seeds 0-2 and 6-9 and lowered BC w/o translation from 55.0 to 48.1 %; in peg
    insertion the same noise lowered LfDT (README, twin development)."""
    start_states: Literal["evaluation", "development"] = "evaluation"
    """Seed block of the twin's trial start states: 'evaluation' (the reported results) or 'development' (a disjoint
    block for choosing settings, with twin seeds 0-2 and 6-8: `dvc exp run -S twin.start_states=development`)."""

    def translator_for(self, task: str) -> TranslatorConfig:
        """The translator settings of one task: ``translator`` with the task's entry of ``task_translator``."""
        return TranslatorConfig.model_validate({**self.translator.model_dump(), **self.task_translator.get(task, {})})

    def bc_for(self, task: str) -> BCConfig:
        """The BC settings of one task: ``bc`` with the task's entry of ``task_bc``."""
        return BCConfig.model_validate({**self.bc.model_dump(), **self.task_bc.get(task, {})})

    @model_validator(mode="after")
    def _learned_kinematics(self) -> TwinParams:
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"seeds has duplicates: {self.seeds}")
        # names are checked against lfdt.tasks.registry.PLANAR by the preflight stage and the twin stages (checking
        # them here would make every stage depend on the twin's task modules)
        if len(set(self.tasks)) != len(self.tasks):
            raise ValueError(f"tasks has duplicates: {self.tasks}")
        _check_episodes(self.random_samples, self.random_episode_steps, "random_samples", "random_episode_steps")
        if self.demos_per_pairing * TWIN_ATTEMPTS_PER_DEMO > MAX_EPISODES:
            raise ValueError(f"demos_per_pairing = {self.demos_per_pairing}: the twin tries up to "
                             f"{TWIN_ATTEMPTS_PER_DEMO} takes per demonstration, and a seed has {MAX_EPISODES} start "
                             f"states; at most {MAX_EPISODES // TWIN_ATTEMPTS_PER_DEMO}")
        for task in [None, *self.task_translator]:
            cfg = self.translator if task is None else self.translator_for(task)  # validates the task's entry
            where = "translator" if task is None else f"task_translator.{task}"
            if cfg.kinematics != "learned":
                raise ValueError(f"{where}: kinematics = {cfg.kinematics!r}: the twin's states are end positions with "
                                 "no joint angles, so G must output them ('learned')")
        for task in self.task_bc:
            self.bc_for(task)  # validates the task's entry
        return self


class Params(Strict):
    """The whole params.yaml."""

    device: Annotated[str, Field(pattern=r"^(cpu|cuda(:[0-9]+)?|mps)$")] = "cpu"
    """Torch device of the training stages (experts, dynamics, translator, BC, twin): cpu, cuda, cuda:N or mps."""
    env: EnvConfig = EnvConfig()
    """The simulated task."""
    experts: ExpertsConfig = ExpertsConfig()
    """SAC experts."""
    random: RandomConfig = RandomConfig()
    """Random-motion collection."""
    demos: DemosConfig = DemosConfig()
    """Demonstration collection."""
    dynamics: DynamicsConfig = DynamicsConfig()
    """Forward and inverse dynamics of domain Y."""
    grid: GridConfig = GridConfig()
    """Matrix values of the translation, BC and evaluation stages."""
    translator: TranslatorConfig = TranslatorConfig()
    """Domain translation (G, D and their losses)."""
    track: TrackConfig = TrackConfig()
    """Re-execution of the translated demonstrations in Y (the lfdt_track row)."""
    bc: BCConfig = BCConfig()
    """Behaviour cloning."""
    evaluation: EvaluationConfig = EvaluationConfig()
    """Evaluation of the BC policies in domain Y."""
    twin: TwinParams = TwinParams()
    """The real-robot tasks on the MuJoCo twin (or on the robots)."""

    @model_validator(mode="after")
    def _enough_demos(self) -> Params:
        if max(self.grid.demos) > self.demos.per_pairing:
            raise ValueError(f"grid.demos asks for {max(self.grid.demos)} demonstrations per pairing but "
                             f"demos.per_pairing collects only {self.demos.per_pairing}")
        for demos in self.grid.demos:
            _check_holdout(demos, self.translator.holdout_fraction, "grid.demos", "translator.holdout_fraction")
        if self.twin.backend == "sim":  # the robots' recordings are counted by the twin's stages
            for task in self.twin.tasks:
                where = f"twin.task_translator.{task}" if task in self.twin.task_translator else "twin.translator"
                _check_holdout(self.twin.demos_per_pairing, self.twin.translator_for(task).holdout_fraction,
                               "twin.demos_per_pairing", f"{where}.holdout_fraction")
        return self


def held_out_count(episodes: int, fraction: float) -> int:
    """Demonstrations (whole episodes) of a pairing that a translator holds out for checkpoint selection: none at
    ``fraction`` 0, else at least one (:func:`lfdt.translation.transitions.split_held_out`)."""
    return 0 if fraction <= 0 else max(1, int(round(fraction * episodes)))


def _check_holdout(episodes: int, fraction: float, episodes_key: str, fraction_key: str) -> None:
    held = held_out_count(episodes, fraction)
    if held and held >= episodes:
        raise ValueError(f"{episodes_key} = {episodes} with {fraction_key} = {fraction:g}: {held} of {episodes} "
                         "demonstrations per pairing would be held out, none left to train the translator on")


class ParamsError(ValueError):
    """params.yaml failed validation; the message names each offending key and value."""


def _field(loc: tuple) -> FieldInfo | None:
    """The schema field at an error's location (None inside a list or a free-form mapping)."""
    model: Any = Params
    field = None
    for part in loc:
        if not (isinstance(model, type) and issubclass(model, BaseModel)) or part not in model.model_fields:
            return None
        field = model.model_fields[part]
        model = field.annotation
    return field


def _accepted(field: FieldInfo | None) -> str:
    """What a number field accepts, as a note to its error: ' (accepted: an integer > 0 and <= 2147483647)'."""
    kind = {int: "an integer", float: "a number"}.get(field.annotation) if field is not None else None
    if kind is None:
        return ""
    bounds = [f"{op} {getattr(m, attr)}" for m in field.metadata
              for attr, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
              if getattr(m, attr, None) is not None]
    return f" (accepted: {kind}{' ' + ' and '.join(bounds) if bounds else ''})"


def _format_errors(err: ValidationError) -> str:
    """Every problem of a validation, in one line (a stage's error is one line): ``key = value: what``, joined by
    '; '."""
    problems = []
    for e in err.errors():
        key = ".".join(str(p) for p in e["loc"] if p != "") or "(top level)"
        value = e.get("input")
        msg = " ".join(e["msg"].removeprefix("Value error, ").split())
        if isinstance(value, dict):  # a whole section: the message says what is wrong in it
            problems.append(f"{key}: {msg}")
            continue
        shown = " ".join(repr(value).split())
        problems.append(f"{key} = {shown if len(shown) <= 80 else shown[:77] + '...'}: {msg}"
                        f"{_accepted(_field(e['loc']))}")
    head = "invalid params: " if len(problems) == 1 else f"invalid params ({len(problems)} problems): "
    return head + "; ".join(problems)


def missing_keys(raw: dict, model: type[BaseModel] = Params, prefix: str = "") -> list[str]:
    """The schema's keys that ``raw`` leaves out, dotted; a missing section is named once, not key by key."""
    out = []
    for name, field in model.model_fields.items():
        if name not in raw:
            out.append(prefix + name)
        elif isinstance(field.annotation, type) and issubclass(field.annotation, BaseModel) \
                and isinstance(raw[name], dict):
            out += missing_keys(raw[name], field.annotation, f"{prefix}{name}.")
    return out


def _default_of(key: str) -> Any:
    value: Any = Params()
    for part in key.split("."):
        value = getattr(value, part)
    return value


def require_complete(raw: dict, source: str | Path) -> None:
    """ParamsError naming every key of the schema that ``raw`` (read from ``source``) leaves out. A stage would use
    lfdt/config.py's default in its place without a word (and DVC reruns it for the deleted line), so params files
    write every key out, as the repository's params.yaml (rendered from the schema) does."""
    missing = missing_keys(raw)
    if not missing:
        return
    named = []
    for key in missing[:6]:
        default = _default_of(key)
        named.append(f"section {key}" if isinstance(default, BaseModel) else f"{key} (default {_yaml_scalar(default)})")
    more = f" and {len(missing) - 6} more" if len(missing) > 6 else ""
    raise ParamsError(f"invalid params: {source} lacks {', '.join(named)}{more}: every key must be written out, as in "
                      "the repository's params.yaml (a stage would otherwise use lfdt/config.py's default without a "
                      "word)")


def validate_params(raw: dict | None) -> Params:
    """Validate a params dict; raises ParamsError naming every bad key and value."""
    if raw is not None and not isinstance(raw, dict):
        raise ParamsError(f"invalid params: the top level must be a mapping, got {type(raw).__name__}")
    try:
        return Params.model_validate(raw or {})
    except ValidationError as err:
        raise ParamsError(_format_errors(err)) from None


def load_params(path: str | Path = "params.yaml") -> Params:
    """Read and validate params.yaml: every value valid and every key present (:func:`require_complete`). A file
    that is missing, not a readable file, not UTF-8 or not YAML, or that writes a key twice, is a ParamsError naming
    it."""
    from lfdt import inputs
    from lfdt.errors import InputError

    path = Path(path)
    try:
        text = inputs.read_text(path, "params file", "a UTF-8 YAML mapping like the repository's params.yaml")
    except InputError as err:
        raise ParamsError(str(err)) from None
    try:
        raw = parse_yaml(text)
    except yaml.YAMLError as err:
        raise ParamsError(f"{path} is not valid YAML: {yaml_problem(err)}") from None
    params = validate_params(raw)  # first: a wrong value or an unknown key is named before a missing one
    require_complete(raw, path)
    return params


class _UniqueKeyLoader(yaml.SafeLoader):
    """YAML's safe loader, refusing a key written twice in one mapping (plain YAML keeps the last one without a
    word, so a value added below an existing key would silently replace it)."""


def _unique_mapping(loader: _UniqueKeyLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    first: dict[Any, int] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        try:
            seen = key in first
        except TypeError:  # an unhashable key: the safe loader's own error names it
            continue
        if seen:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping", node.start_mark,
                f"found the key {key!r} a second time (first on line {first[key]})", key_node.start_mark)
        first[key] = key_node.start_mark.line + 1
    return yaml.SafeLoader.construct_mapping(loader, node, deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _unique_mapping)


def yaml_problem(err: yaml.YAMLError) -> str:
    """A YAML error in one line: where (line and column of the text) and what."""
    if not isinstance(err, yaml.MarkedYAMLError):
        return " ".join(str(err).split())
    mark = err.problem_mark or err.context_mark
    where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
    what = "; ".join(part for part in (err.problem, err.context) if part)
    return where + " ".join(what.split())


def parse_yaml(text: str) -> Any:
    """Params YAML text as Python objects (empty -> {}); a key written twice in one mapping is a ``yaml.YAMLError``."""
    return yaml.load(text, Loader=_UniqueKeyLoader) or {}  # noqa: S506 (a SafeLoader subclass)


def _yaml_scalar(v: Any) -> str:
    return yaml.safe_dump(v, default_flow_style=True, width=1000).strip().removesuffix("...").strip()


def render_defaults(model: type[BaseModel] = None, instance: BaseModel | None = None, indent: int = 0) -> str:
    """params.yaml text of a config's defaults, every key commented with its field docstring."""
    instance = instance if instance is not None else (model or Params)()
    lines = []
    pad = "  " * indent
    for name, field in type(instance).model_fields.items():
        value = getattr(instance, name)
        doc = (field.description or "").replace("\n", " ")
        if isinstance(value, BaseModel):
            lines.append(f"{pad}# {doc}" if doc else "")
            lines.append(f"{pad}{name}:")
            lines.append(render_defaults(instance=value, indent=indent + 1))
        else:
            lines.append(f"{pad}{name}: {_yaml_scalar(value)}  # {doc}")
    return "\n".join(line for line in lines if line != "")
