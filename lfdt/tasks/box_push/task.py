"""The box push as a task (:class:`lfdt.tasks.base.Task`): its name, its layout, its environment per domain.

It satisfies the protocol by its shape and does not import :mod:`lfdt.tasks.base` (whose planar tasks bring the
twin along): the box push's stages must not depend on the twin's code.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lfdt.tasks.box_push.columns import BOX_PUSH

if TYPE_CHECKING:
    from lfdt.config import EnvConfig
    from lfdt.tasks.box_push.env import BoxPushEnv, BoxPushModel


class BoxPush:
    """Table I's simulated box push: the MuJoCo scene of :mod:`lfdt.tasks.box_push.env` (params ``env``)."""

    name = "box_push"
    layout = BOX_PUSH
    action_bounds = (-1.0, 1.0)
    """Normalised torque commands (times a joint's gear gives N m): a policy's actions are clipped to this range."""

    def make_env(self, domain: str, config: EnvConfig | dict | None = None, render_mode: str | None = None,
                 size: int = 240, scene: BoxPushModel | None = None) -> BoxPushEnv:
        """The box push in ``domain`` (``config``: params ``env``, defaults if None), rendering ``size`` pixels
        square; ``scene``: a compiled scene of that domain and config to share (many environments at once)."""
        from lfdt.tasks.box_push.env import BoxPushEnv

        return BoxPushEnv(domain, config, render_mode=render_mode, width=size, height=size, scene=scene)


TASK = BoxPush()
"""The registry's entry (:data:`lfdt.tasks.registry.TASKS`)."""
