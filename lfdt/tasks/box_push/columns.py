"""The box push's column layout: which arm has how many joints, and the box.

Every arm contributes, in this order, its joint angles ``q*`` (rad), joint velocities ``dq*`` (rad/s) and end
position ``ee_x, ee_y`` (m, world frame). The object (box) contributes ``x, y`` (m) and ``yaw`` (rad). Column
names are ``<arm>.<quantity>``, e.g. ``r1.q0``, ``h.ee_y``, ``box.yaw``; the box push's stages select groups by
name through this module. Domains, slots and prefixes are every task's (:mod:`lfdt.layout`).
"""

from __future__ import annotations

from lfdt.config import EnvConfig
from lfdt.layout import (
    ACTION_PREFIX,
    DOMAIN_ARMS,
    DOMAINS,
    HUMAN_ACTION_PREFIX,
    NEXT_STATE_PREFIX,
    STATE_PREFIX,
    TaskLayout,
    robot_arm,
)

ARM_JOINTS: dict[str, int] = {"r1": EnvConfig.JOINTS["robot"], "r2": EnvConfig.JOINTS["robot"],
                              "h": EnvConfig.JOINTS["human"]}
"""Joints per arm: the scene's (params ``env``; :attr:`lfdt.config.EnvConfig.JOINTS`)."""
OBJECT_COLUMNS: tuple[str, ...] = ("box.x", "box.y", "box.yaw")


def arm_columns(arm: str) -> list[str]:
    """State column names of one arm: joint angles, joint velocities, end position."""
    n = ARM_JOINTS[arm]
    return [f"{arm}.q{i}" for i in range(n)] + [f"{arm}.dq{i}" for i in range(n)] + [f"{arm}.ee_x", f"{arm}.ee_y"]


def arm_action_columns(arm: str) -> list[str]:
    """Action column names of one arm: one normalised torque command per joint."""
    return [f"{arm}.tau{i}" for i in range(ARM_JOINTS[arm])]


def state_columns(domain: str) -> list[str]:
    """State column names of a box-push domain, in observation-vector order (:data:`BOX_PUSH`'s)."""
    return BOX_PUSH.state_columns(domain)


def action_columns(domain: str) -> list[str]:
    """Action column names of a box-push domain, in action-vector order (both slots; :data:`BOX_PUSH`'s)."""
    return BOX_PUSH.action_columns(domain)


def groups(domain: str) -> dict[str, list[str]]:
    """Named column groups of a domain: the paper's x^H, x^Ri, x^O (X) or y^R1, y^R2, y^O (Y)."""
    if domain == "Y":
        return {"y^R1": arm_columns("r1"), "y^R2": arm_columns("r2"), "y^O": list(OBJECT_COLUMNS)}
    ri = robot_arm(domain)
    return {"x^H": arm_columns("h"), f"x^R{ri[1]}": arm_columns(ri), "x^O": list(OBJECT_COLUMNS)}


def describe() -> dict:
    """The whole layout as a JSON-serialisable dict (stored in every Parquet file's metadata)."""
    return {
        "slots": "state = [slot-1 arm, slot-2 arm, object]; slot 1 is Robot1's place (left), slot 2 Robot2's",
        "domains": {d: {"arms": list(DOMAIN_ARMS[d]), "state": state_columns(d), "action": action_columns(d),
                        "groups": groups(d)} for d in DOMAINS},
        "units": {"q": "rad", "dq": "rad/s", "ee_x/ee_y/box.x/box.y": "m, world frame", "box.yaw": "rad",
                  "tau": "normalised torque command in [-1, 1] (times the actuator gear gives N m)"},
        "prefixes": {"state": STATE_PREFIX, "next_state": NEXT_STATE_PREFIX, "action": ACTION_PREFIX,
                     "human_action": HUMAN_ACTION_PREFIX},
    }


BOX_PUSH = TaskLayout("box_push", {a: arm_columns(a) for a in ARM_JOINTS},
                      {a: arm_action_columns(a) for a in ARM_JOINTS}, list(OBJECT_COLUMNS),
                      {a: [f"{a}.ee_x", f"{a}.ee_y"] for a in ARM_JOINTS}, hand_actions_recorded=True)
"""The simulated 2D dual-arm box push (the module-level functions above describe the same layout)."""
