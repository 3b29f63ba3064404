"""The rows of Table I: one record per method, the single place that says what a method is.

Config validation, the stages, the report and the plots read these records; nothing else compares method
names. Adding an ablation is one entry here (with its translator overrides) plus its test.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    from lfdt.config import TranslatorConfig


@dataclass(frozen=True)
class Method:
    """One way of getting a dual-arm policy for domain Y."""

    name: str
    """Identifier used in params.yaml (grid), file names and MLflow tags."""
    title: str
    """Row title in Table I."""
    data: Literal["raw", "translated", "executed"]
    """What BC learns from: the raw demonstrations of X (one policy per robot), translated demonstrations, or
    translated demonstrations re-executed in Y (:mod:`lfdt.tasks.box_push.reexecute`)."""
    translator: str | None = None
    """The translator method whose output this method reads (None: no translation)."""
    overrides: dict[str, float] = field(default_factory=dict)
    """For a method that trains a translator: translator params it sets (an ablation sets one weight to zero)."""
    paper: dict[int, float] = field(default_factory=dict)
    """The paper's Table I success rate in % by demonstrations per pairing (empty: not in the paper)."""
    colour: str = "tab:gray"
    """Plot colour."""
    ours: bool = False
    """Our extension, not a row of the paper."""

    @property
    def trains_translator(self) -> bool:
        """True when this method has a translator of its own (its name is a translator method)."""
        return self.translator == self.name


METHODS: dict[str, Method] = {m.name: m for m in (
    Method("bc_no_translation", "BC w/o translation", "raw",
           paper={50: 28.3, 100: 6.7, 200: 26.7}, colour="tab:gray"),
    Method("lfdt_no_dyn", "LfDT w/o dynamics-consistency", "translated", translator="lfdt_no_dyn",
           overrides={"lambda_dyn": 0.0}, paper={50: 51.7, 100: 61.7, 200: 51.7}, colour="tab:orange"),
    Method("lfdt_no_id", "LfDT w/o partial identity", "translated", translator="lfdt_no_id",
           overrides={"lambda_id": 0.0}, paper={50: 0.0, 100: 0.0, 200: 0.0}, colour="tab:red"),
    Method("lfdt", "LfDT", "translated", translator="lfdt", paper={50: 80.0, 100: 81.7, 200: 71.7},
           colour="tab:blue"),
    Method("lfdt_track", "LfDT + re-execution in Y (ours)", "executed", translator="lfdt", colour="tab:purple",
           ours=True),
)}
"""Every method, in Table I's row order."""


def get(name: str) -> Method:
    """The method called ``name``; a ValueError lists the known ones."""
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; expected one of {list(METHODS)}")
    return METHODS[name]


def translator_methods() -> list[str]:
    """Methods that train a translator of their own."""
    return [m.name for m in METHODS.values() if m.trains_translator]


def translator_config(method: str, cfg: TranslatorConfig) -> TranslatorConfig:
    """The translator config of a translator method (an ablation sets one weight to zero: its overrides)."""
    m = get(method)
    if not m.trains_translator:
        raise ValueError(f"{method!r} trains no translator; translator methods: {translator_methods()}")
    return cfg.model_copy(update=m.overrides)
