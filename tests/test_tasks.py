"""The task registry: a task is one module behind one interface, and a new one needs nothing else changed."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lfdt import data
from lfdt.rig.sim import SimRig
from lfdt.tasks import registry
from lfdt.tasks.base import PlanarTask, Task
from lfdt.tasks.planar_env import TwinEnv
from lfdt.twin import collect as twin_collect

ROOT = Path(__file__).resolve().parents[1]


class PuckSlide(PlanarTask):
    """A toy task: both ends push a round puck 5 cm ahead (+y); success when it gets there."""

    name, plane, angle, angle_axis = "puck_slide", ("x", "y"), "yaw", "z"
    workspace = np.array([[-0.15, 0.0], [0.15, 0.3]])

    def object_xml(self, arms):
        return ('<body name="obj"><joint name="px" type="slide" axis="1 0 0" damping="4"/>'
                '<joint name="py" type="slide" axis="0 1 0" damping="4"/>'
                '<geom type="cylinder" size="0.04 0.01" mass="0.2"/></body>')

    def camera_xml(self):
        return '<camera name="view" pos="0 0.1 0.6"/>'

    def reset(self, env, rng):
        env.data.qpos[env.model.jnt_qposadr[env.model.joint("py").id]] = 0.1
        return [np.array([-0.02, 0.045]), np.array([0.02, 0.045])]

    def info(self, env):
        return {"is_success": bool(env.object_pose()[1] > 0.15)}

    def program_waypoint(self, robot_slot, start, obs, goal_line=None):
        return start + (0.0, 0.06)

    def person_target(self, env, human_slot, robot_slot, obs):
        return obs[2 * robot_slot:2 * robot_slot + 2] + ((0.04 if human_slot == 1 else -0.04), 0.0)

    def example_rig(self):
        return {}, {}, {}, {}


PUCK_SLIDE = PuckSlide()


def test_registry_names_every_task_and_refuses_others() -> None:
    assert registry.NAMES == ("box_push", "block_push", "peg_insertion")
    assert registry.PLANAR == ("block_push", "peg_insertion")
    for name in registry.NAMES:
        task = registry.get(name)
        assert isinstance(task, Task) and task.name == name and task.layout.name == name
        assert isinstance(task, PlanarTask) == (name in registry.PLANAR)
    for name in registry.PLANAR:
        assert len(registry.get(name).layout.state_columns("Y")) == 7
    with pytest.raises(ValueError, match=r"unknown task 'slide'.*block_push"):
        registry.get("slide")


def test_the_registry_imports_a_task_only_when_asked_for() -> None:
    code = ("import sys; from lfdt.tasks import registry; "
            "loaded = lambda: sorted(m for m in sys.modules if m.startswith(('lfdt.tasks.', 'lfdt.twin')))"
            "; print(loaded()); registry.get('box_push'); print(loaded())")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    before, after = out.stdout.splitlines()
    assert before == "['lfdt.tasks.registry']"
    assert "lfdt.tasks.box_push.task" in after and "block_push" not in after and "lfdt.twin" not in after


@pytest.mark.parametrize("name", registry.NAMES)
def test_every_task_makes_its_environment_in_every_domain(name) -> None:
    """The protocol the task-agnostic code relies on: observations in the layout's order, success in the info."""
    task = registry.get(name)
    for domain in ("Y", "R1H", "HR2"):
        env = task.make_env(domain)
        obs, _ = env.reset(seed=0)
        assert obs.shape == (len(task.layout.state_columns(domain)),)
        assert env.action_space.shape is not None
        _, _, terminated, _, info = env.step(env.action_space.sample() * 0)
        assert terminated == info["is_success"]
        env.close()


def test_a_new_task_is_one_class_and_one_entry(monkeypatch, tmp_path) -> None:
    monkeypatch.setitem(registry.TASKS, "puck_slide", f"{__name__}:PUCK_SLIDE")
    assert registry.get("puck_slide") is PUCK_SLIDE
    env = registry.get("puck_slide").make_env("Y")
    assert isinstance(env, TwinEnv)
    obs, info = env.reset(seed=0)
    assert obs.shape == (7,) and not info["is_success"]
    assert env.layout.state_columns("Y")[-3:] == ["obj.x", "obj.y", "obj.yaw"]
    # its demonstrations and random motion come from the shared loops, in the shared data conventions
    stats = twin_collect.record_demos("puck_slide", "R1H", 2, 0, tmp_path / "demos")
    assert stats["demonstrations"] == 2
    data.check_transitions(tmp_path / "demos", "demos", "R1H", env.layout)
    assert twin_collect.record_random("puck_slide", "HR2", 25, 10, 0, tmp_path / "random") == 25
    with SimRig("puck_slide", "Y") as rig:
        assert rig.state_columns() == env.layout.state_columns("Y")


def test_no_module_branches_on_a_task_name() -> None:
    out = subprocess.run(["grep", "-rnE", r"task ==|task in \(|== \"(block_push|peg_insertion)\"", "lfdt"],
                         cwd=ROOT, capture_output=True, text=True)
    assert out.stdout == "", out.stdout
