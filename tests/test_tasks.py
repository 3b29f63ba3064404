"""The task registry: a task is one module behind one interface, and a new one needs nothing else changed."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from lfdt import data, tasks
from lfdt.robot.sim_rig import SimRig
from lfdt.tasks.base import PlanarTask
from lfdt.twin import pipeline as twin_pipeline
from lfdt.twin.env import TwinEnv

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


def test_registry_names_every_task_and_refuses_others() -> None:
    assert tasks.NAMES == ("block_push", "peg_insertion")
    for name, task in tasks.TASKS.items():
        assert task.name == name and task.layout.name == name
        assert len(task.layout.state_columns("Y")) == 7
    with pytest.raises(ValueError, match=r"unknown task 'slide'.*block_push"):
        tasks.get("slide")


def test_a_new_task_is_one_class_and_one_entry(monkeypatch, tmp_path) -> None:
    monkeypatch.setitem(tasks.TASKS, "puck_slide", PuckSlide())
    env = TwinEnv("puck_slide", "Y")
    obs, info = env.reset(seed=0)
    assert obs.shape == (7,) and not info["is_success"]
    assert env.layout.state_columns("Y")[-3:] == ["obj.x", "obj.y", "obj.yaw"]
    # its demonstrations and random motion come from the shared loops, in the shared data conventions
    stats = twin_pipeline.record_demos("puck_slide", "R1H", 2, 0, tmp_path / "demos")
    assert stats["demonstrations"] == 2
    data.check_transitions(tmp_path / "demos", "demos", "R1H", env.layout)
    assert twin_pipeline.record_random("puck_slide", "HR2", 25, 10, 0, tmp_path / "random") == 25
    with SimRig("puck_slide", "Y") as rig:
        assert rig.state_columns() == env.layout.state_columns("Y")


def test_no_module_branches_on_a_task_name() -> None:
    out = subprocess.run(["grep", "-rnE", r"task ==|task in \(|== \"(block_push|peg_insertion)\"", "lfdt"],
                         cwd=ROOT, capture_output=True, text=True)
    assert out.stdout == "", out.stdout
