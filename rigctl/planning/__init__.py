"""Planning a shot: the paper's equations (1) and (2) as array functions (:mod:`.planner`) and their use on a
rig, every camera pair against the parallax budget, with the disparity search range depth uses
(:mod:`.report`: :func:`plan_rig`; :mod:`.text`: :func:`format_plan`)."""

from rigctl.planning import planner
from rigctl.planning.report import PairPlan, Plan, plan_rig
from rigctl.planning.text import format_plan

__all__ = ["PairPlan", "Plan", "format_plan", "plan_rig", "planner"]
