"""The tasks of the posture problem, one class per file, each registered under its ``type``
(:func:`register_task`): ``position``, ``pose``, ``orientation``, ``axis``, ``gaze``,
``region``, ``relative``, ``distance``, ``com`` and ``joints``. Write your own by subclassing
:class:`Task` (see its module, :mod:`posturegen.terms.tasks.base`)."""

from .axis import AxisTask
from .base import Task, read_task, register_task, task_types
from .com import ComTask
from .distance import DistanceTask
from .fields import Field
from .frames import Frames, NumericFrames, SymbolicFrames
from .gaze import GazeTask
from .joints import JointsTask
from .orientation import OrientationTask
from .position import PoseTask, PositionTask
from .region import RegionTask
from .relative import RelativeTask

__all__ = [
    "AxisTask",
    "ComTask",
    "DistanceTask",
    "Field",
    "Frames",
    "GazeTask",
    "JointsTask",
    "NumericFrames",
    "OrientationTask",
    "PoseTask",
    "PositionTask",
    "RegionTask",
    "RelativeTask",
    "SymbolicFrames",
    "Task",
    "read_task",
    "register_task",
    "task_types",
]
