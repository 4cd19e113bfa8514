"""A contact planner on top of the posture generator (``posturegen plan``): a focal search
(bounded-suboptimal A*) over stances whose transitions are checked by posture generation
(paper sec. IV-E).

    >>> report = pg.plan("stairs", "out/", robot="atlas", workers=2)
    >>> report.success, report.stats.postures
"""

from __future__ import annotations

from .api import PlanReport, plan
from .goal import Goal, parse_goal
from .rules import PatchRule, Rules, default_rules, parse_rules
from .search import Budget, Stats

__all__ = [
    "Budget",
    "Goal",
    "PatchRule",
    "PlanReport",
    "Rules",
    "Stats",
    "default_rules",
    "parse_goal",
    "parse_rules",
    "plan",
]
