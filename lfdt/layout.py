"""What every task's layout shares: domains, slots, the arms in each domain and the column prefixes.

State vectors are the concatenation ``[slot-1 arm, slot-2 arm, object]``. Slot 1 is where
Robot1 stands (left, x < 0), slot 2 where Robot2 stands (right). In domain X the human
stand-in takes one slot: R1H = (Robot1, Human), HR2 = (Human, Robot2). Domain Y = (Robot1, Robot2).

Which columns an arm and the object contribute is the task's own :class:`TaskLayout`: the box push's is
:data:`lfdt.tasks.box_push.columns.BOX_PUSH` (joint angles, joint velocities and end position per arm), a
real-robot task's comes from :attr:`lfdt.tasks.base.PlanarTask.layout`. Column names are ``<arm>.<quantity>``.
"""

from __future__ import annotations

from typing import Literal

Arm = Literal["r1", "r2", "h"]
Domain = Literal["Y", "R1H", "HR2"]

DOMAINS: tuple[str, ...] = ("Y", "R1H", "HR2")
PAIRINGS: tuple[str, ...] = ("R1H", "HR2")

ARM_TITLES: dict[str, str] = {"r1": "Robot1", "r2": "Robot2", "h": "Human stand-in"}
DOMAIN_ARMS: dict[str, tuple[str, str]] = {"Y": ("r1", "r2"), "R1H": ("r1", "h"), "HR2": ("h", "r2")}

STATE_PREFIX = "state."
NEXT_STATE_PREFIX = "next_state."
ACTION_PREFIX = "action."
HUMAN_ACTION_PREFIX = "human_action."


def robot_arm(pairing: str) -> str:
    """The robot that is really there in a pairing of domain X ('r1' for R1H, 'r2' for HR2)."""
    if pairing not in PAIRINGS:
        raise ValueError(f"unknown pairing {pairing!r}; expected one of {PAIRINGS}")
    return "r1" if pairing == "R1H" else "r2"


class TaskLayout:
    """The column layout of one task: state columns per arm, action columns per arm, object columns.

    Domains and slots are shared by every task (:data:`DOMAIN_ARMS`); the box push of the simulated
    experiment is :data:`lfdt.tasks.box_push.columns.BOX_PUSH`, the real-robot tasks' layouts come from
    :mod:`lfdt.tasks`.
    """

    def __init__(self, name: str, arm_cols: dict[str, list[str]], action_cols: dict[str, list[str]],
                 object_cols: list[str], position_cols: dict[str, list[str]], hand_actions_recorded: bool = False):
        self.name = name
        self.arm_cols = {k: list(v) for k, v in arm_cols.items()}
        self.action_cols = {k: list(v) for k, v in action_cols.items()}
        self.object_cols = list(object_cols)
        self.position_cols = {k: list(v) for k, v in position_cols.items()}
        """Per arm, the columns of its end (hand) position in the world frame."""
        self.hand_actions_recorded = hand_actions_recorded
        """Whether demonstrations record the human's actions too (a simulated stand-in's torques; a tracked hand has
        none)."""

    def arm_columns(self, arm: str) -> list[str]:
        """State columns of one arm."""
        return self.arm_cols[arm]

    def arm_action_columns(self, arm: str) -> list[str]:
        """Action columns of one arm."""
        return self.action_cols[arm]

    def state_columns(self, domain: str) -> list[str]:
        """State columns of a domain, in observation order [slot 1, slot 2, object]."""
        a1, a2 = DOMAIN_ARMS[domain]
        return self.arm_cols[a1] + self.arm_cols[a2] + self.object_cols

    def action_columns(self, domain: str) -> list[str]:
        """Action columns of a domain (both slots)."""
        a1, a2 = DOMAIN_ARMS[domain]
        return self.action_cols[a1] + self.action_cols[a2]

    def robot_y_slice(self, pairing: str) -> slice:
        """Where the pairing's real robot sits in a Y state (y^R1 first, y^R2 second)."""
        n = len(self.arm_cols["r1"])
        return slice(0, n) if robot_arm(pairing) == "r1" else slice(n, 2 * n)

    def canonical_x_columns(self, pairing: str) -> list[str]:
        """A pairing's state in the translator's order: the robot that is there, the human, the object."""
        return self.arm_cols[robot_arm(pairing)] + self.arm_cols["h"] + self.object_cols

    def describe(self) -> dict:
        """JSON-serialisable description (stored in Parquet metadata)."""
        return {"task": self.name, "domains": {d: {"arms": list(DOMAIN_ARMS[d]), "state": self.state_columns(d),
                                                   "action": self.action_columns(d)} for d in DOMAINS}}
